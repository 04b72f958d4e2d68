// Tile renderer, the device order's key passes (--sort gpu, splatgl/renderers/tile_device.py),
// by u_stage:
//   0 (over the tiles): clear tile_ranges; reset the rasterize passes to one.
//   1 (over the keys, between the two sorts): the sorter's keys become the tiles of the keys
//     the depth sort ordered (dev_values holds each one's emission place).
//   2 (over the keys, after the tile sort): tile_ranges from where the tile changes, and
//     tile_order, the sorted keys' splat indices, which the rasterizer reads.
//   3 (over the tiles): the rasterize passes the longest list needs, as indirect dispatches.
//   4 (over the splats, DEVICE_PRESORT): the depth sort's keys, the float bits of view z (all
//     ones for a splat that touches no tile), and values, the splat indices.
// DEVICE_PRESORT: the sorted values are already the splat indices (no emission places).
// The keys' count and dispatch sizes come from tile_scan.comp's state: nothing is read back.
// Twin: splatgl/renderers/tile_device.py ranges_twin().
#define DEVICE_SORT 1
#define TILE_STATE 1
#define TILE_ORDER 1
#define TILE_DEV_KEYS 1
#include "lib/tile_common.glsl"

layout(local_size_x = SPLAT_GROUP) in;

uniform uint u_stage;
uniform uint u_tiles;         // tiles in the grid
uniform uvec3 u_raster_args;  // one rasterize pass's groups (tiles x, band rows, 1)
uniform uint u_emit_slots;    // ts_args: emit slots first, then u_raster_slots passes
uniform uint u_raster_slots;
uniform uint u_splats;        // splats N (stage 4)

void main() {
    uint i = splat_invocation();
    if (u_stage == 0u) {
        if (i < u_tiles) tile_ranges[i] = uvec2(0u);
        if (i == 0u) {
            ts_passes = 1u;
            for (uint p = 0u; p < u_raster_slots; ++p)
                ts_args[u_emit_slots + p] = p == 0u ? uvec4(u_raster_args, 0u) : uvec4(0u);
        }
        return;
    }
    if (u_stage == 4u) {
        if (i == 0u) ts_splats = u_splats;   // the sort reads its count here, not from the host
        if (i >= u_splats) return;
        dev_keys[i] = tiles_touched[i] > 0u ? floatBitsToUint(proj_mean_depth[i].z) : ~0u;
        dev_values[i] = i;
        return;
    }
    if (u_stage == 3u) {
        if (i >= u_tiles) return;
        uvec2 r = tile_ranges[i];
        uint need = (r.y - r.x + uint(TILE_LIST_CHUNK) - 1u) / uint(TILE_LIST_CHUNK);
        if (need > 1u) {
            need = min(need, u_raster_slots);
            atomicMax(ts_passes, need);
            for (uint p = 1u; p < need; ++p) ts_args[u_emit_slots + p] = uvec4(u_raster_args, 0u);
        }
        return;
    }
    uint n = ts_sort_count;
    if (i >= n) return;
    if (u_stage == 1u) {
        dev_keys[i] = sort_keys[dev_values[i]].y;  // the reference key's high word: the tile
        return;
    }
    uint tile = dev_keys[i];
    if (i == 0u || dev_keys[i - 1u] != tile) tile_ranges[tile].x = i;
    if (i + 1u == n || dev_keys[i + 1u] != tile) tile_ranges[tile].y = i + 1u;
#ifdef DEVICE_PRESORT
    tile_order[i] = dev_values[i];
#else
    tile_order[i] = sort_values[dev_values[i]];
#endif
}
