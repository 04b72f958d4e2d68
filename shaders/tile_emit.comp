// Tile renderer, stage 3 "emit_keys": one invocation per splat (3DGS duplicateWithKeys).
// Twin: splatgl/reference/binning.py emit_keys().
// Splat i writes one key per tile of its rectangle, rows top to bottom and each row left to right, starting at tile_offsets[i]; the
// key orders by tile_id = y * tiles_x + x, then by the float bits of view z (lib/tile_common).
// A dispatch writes the keys u_first .. u_first + TILE_EMIT_CHUNK - 1 of each splat (one loop over
// the rectangle's row-major index): llvmpipe ends an invocation's loops after 65535 iterations
// in all, which one splat covering a 4096 x 4096 image would reach, so splatgl/renderers/tile.py issues
// as many dispatches as the largest rectangle needs (one, below 32768 tiles).
// DEVICE_SORT (--sort gpu): also the radix sorter's keys and values, (depth bits, emission
// place), and splatgl/renderers/tile_device.py issues the chunks indirectly (tile_scan.comp).
// DEVICE_PRESORT (--sort gpu, global order): invocation k emits the k-th nearest splat
// (splat_order) and only the sorter's (tile, splat index): a stable sort by tile then gives
// the (tile, depth) order, ties in index order.
// PER_PIXEL (3DGS): the key's depth is the splat's peak depth along the ray through its centre
// clamped into the box of the tile's pixel centres (lib/peak_depth.glsl; twin
// splatgl/splatmath/peak.py tile_key_bits), clamped below at MIN_KEY_DEPTH, so that each
// pixel's window has little order left to fix.
#ifdef DEVICE_SORT
#define TILE_DEV_KEYS 1
#endif
#ifdef DEVICE_PRESORT
#define TILE_NO_KEYS 1
#define TILE_SPLAT_ORDER 1
#endif
#include "lib/tile_common.glsl"
#if defined(PER_PIXEL) && !defined(SURFEL)
#include "lib/peak_depth.glsl"
uniform vec4 u_rays;    // (cx, cy, fx, fy)
const float MIN_KEY_DEPTH = 1.0e-30;
#endif

layout(local_size_x = SPLAT_GROUP) in;

uniform uint u_count;   // number of splats N
uniform uvec2 u_grid;   // (tiles_x, tiles_y)
uniform uint u_first;   // first key of each splat's rectangle this dispatch writes

void main() {
    uint i = splat_invocation();
    if (i >= u_count) return;
#ifdef DEVICE_PRESORT
    uint base = tile_offsets[i];
    i = splat_order[i];
#else
    uint base = tile_offsets[i];
#endif
    uint touched = tiles_touched[i];
    if (touched <= u_first) return;
    uvec4 rect = proj_rect[i];
    uint width = rect.z - rect.x;
    uint depth_bits = floatBitsToUint(proj_mean_depth[i].z);  // z > near > 0: sign bit clear
    uint last = min(touched, u_first + uint(TILE_EMIT_CHUNK));
    for (uint j = u_first; j < last; ++j) {
        uint y = rect.y + j / width, x = rect.x + j % width;
#if defined(PER_PIXEL) && !defined(SURFEL)
        vec2 lo = vec2(uvec2(x, y) * uint(TILE_SIZE)) + 0.5;
        vec2 at = min(max(proj_mean_depth[i].xy, lo), lo + float(TILE_SIZE - 1));
        float t = peak_depth(proj_peak[3u * i], proj_peak[3u * i + 1u], proj_peak[3u * i + 2u].xy,
                             (at - u_rays.xy) / u_rays.zw);
        depth_bits = floatBitsToUint(max(t, MIN_KEY_DEPTH));
#endif
#if defined(DEVICE_PRESORT)
        dev_keys[base + j] = y * u_grid.x + x;
        dev_values[base + j] = i;
#else
        sort_keys[base + j] = tile_key(y * u_grid.x + x, depth_bits, i);
#ifndef KEY_PACKED
        sort_values[base + j] = i;
#endif
#endif
#if defined(DEVICE_SORT) && !defined(DEVICE_PRESORT)
        dev_keys[base + j] = depth_bits;  // the radix sort's first pass: by depth, stably
        dev_values[base + j] = base + j;  // ... carrying the key's emission place
#endif
    }
}
