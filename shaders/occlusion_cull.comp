// Early termination, splat-level occlusion cull and order-preserving compaction.
//
// Slots [u_start, u_end) of the sorted order form one draw batch.  A splat survives unless its
// quad's screen rectangle lies only on stopped blocks (stop_tiles.comp; every pixel there has
// T < T_MIN, so the depth test would reject each of its fragments anyway) or off the viewport.
// Work group g owns the SEGMENT slots from u_start + g SEGMENT: it writes its survivors, in
// sorted order, to survivors[seg_base + 0..n) and the draw command (4, n, 0, seg_base) as
// command u_cmd_base + g, so a multi-draw-indirect over the batch's commands draws the
// survivors front to back (commands run in order; the instanced attribute reads
// survivors[baseInstance + instance]).  Variants: PREPARED (3DGS after quad_prepass.comp:
// the survivor value is the slot, read back by quad_light.vert), SURFEL (2DGS, the value is the
// splat index for surfel.vert), neither (3DGS vertex path, the splat index for quad.vert).
// Twin: splatgl/splatmath/early_stop.py occlusion_cull().
#include "lib/splat_rect.glsl"

layout(local_size_x = OCCLUSION_GROUP) in;
layout(std430, binding = BINDING_STOP_TILES) readonly buffer StopTiles { uint stopped[]; };
layout(std430, binding = BINDING_SURVIVORS) writeonly buffer Survivors { uint survivors[]; };
// DrawArraysIndirectCommand (count, instanceCount, first, baseInstance) in moderngl's 20-byte
// stride (render_indirect passes stride 20 for arrays too): 5 uints per command.
layout(std430, binding = BINDING_COMMANDS) writeonly buffer Commands { uint commands[]; };
uniform uint u_cmd_base;
#ifdef DEVICE_BATCHES
// The device-resident order (splatgl/renderers/early_stop_device.py): the batch's slots come
// from stop_plan.comp's plan, at uint u_bounds_at; the host dispatches the most groups the batch
// can have, and groups past its end write empty commands (zero instances).
layout(std430, binding = BINDING_STOP_PLAN) readonly buffer Plan { uint plan[]; };
uniform uint u_bounds_at;
#else
uniform uint u_start;
uniform uint u_end;
#endif
uniform ivec2 u_tiles;         // tile grid (columns, rows)
uniform bool u_check_tiles;    // false on the first batch: nothing has stopped yet

shared uint s_scan[OCCLUSION_GROUP];

// Bits of tile `tile`'s stop word (stop_tiles.comp: bit 4 by + bx per block) that the block
// range [blo, bhi] (global block coordinates) covers.
uint covered_blocks(ivec2 tile, ivec2 blo, ivec2 bhi) {
    const int BLOCKS = TILE_SIZE / STOP_BLOCK_SIZE;
    ivec2 a = clamp(blo - BLOCKS * tile, ivec2(0), ivec2(BLOCKS - 1));
    ivec2 b = clamp(bhi - BLOCKS * tile, ivec2(0), ivec2(BLOCKS - 1));
    uint row = (2u << uint(b.x)) - (1u << uint(a.x));          // bits a.x..b.x of one row
    // One bit at the start of each covered row (0x1111-style); the product copies `row` there.
    uint rows = ((1u << uint(BLOCKS * (b.y + 1))) - (1u << uint(BLOCKS * a.y))) / ((1u << BLOCKS) - 1u);
    return row * rows;
}

// A quad covers the pixels whose centres (j + 0.5, i + 0.5) lie in it, all inside the pixel
// range [floor(lo), floor(hi)]; it survives unless that range misses the viewport or every
// stop-mask block it touches is stopped.  A NaN rectangle survives (the draw decides).
bool survives(uint k, out uint value) {
    vec2 lo, hi;
    float area;
    if (!splat_rect(k, lo, hi, value, area)) return false;
    if (any(isnan(vec4(lo, hi)))) return true;
    if (hi.x < 0.0 || hi.y < 0.0 || lo.x >= u_viewport.x || lo.y >= u_viewport.y) return false;
    if (!u_check_tiles) return true;
    ivec2 plo = ivec2(floor(max(lo, vec2(0.0))));
    ivec2 phi = min(ivec2(floor(min(hi, u_viewport))), ivec2(u_viewport) - 1);
    ivec2 tlo = clamp(plo / TILE_SIZE, ivec2(0), u_tiles - 1);
    ivec2 thi = clamp(phi / TILE_SIZE, ivec2(0), u_tiles - 1);
    ivec2 span = thi - tlo + 1;
    if (span.x * span.y > OCCLUSION_MAX_TILES) return true;   // too many to walk (constants.py)
    ivec2 blo = plo / STOP_BLOCK_SIZE, bhi = phi / STOP_BLOCK_SIZE;
    for (int ty = tlo.y; ty <= thi.y; ++ty)
        for (int tx = tlo.x; tx <= thi.x; ++tx) {
            uint need = covered_blocks(ivec2(tx, ty), blo, bhi);
            if ((stopped[ty * u_tiles.x + tx] & need) != need) return true;
        }
    return false;
}

void main() {
#ifdef DEVICE_BATCHES
    uint batch_start = plan[u_bounds_at], batch_end = plan[u_bounds_at + 1u];
#else
    uint batch_start = u_start, batch_end = u_end;
#endif
    uint l = gl_LocalInvocationID.x;
    uint seg_base = batch_start + gl_WorkGroupID.x * (OCCLUSION_GROUP * OCCLUSION_PER_INVOCATION);
#ifdef DEVICE_BATCHES
    if (seg_base >= batch_end) {      // past the batch (the whole group): an empty command
        if (l == 0u) {
            uint c = 5u * (u_cmd_base + gl_WorkGroupID.x);
            commands[c] = 4u;
            commands[c + 1u] = 0u;
            commands[c + 2u] = 0u;
            commands[c + 3u] = 0u;
            commands[c + 4u] = 0u;
        }
        return;
    }
#endif
    uint first = seg_base + l * OCCLUSION_PER_INVOCATION;
    uint values[OCCLUSION_PER_INVOCATION];
    uint count = 0u;
    for (uint j = 0u; j < OCCLUSION_PER_INVOCATION; ++j) {
        uint k = first + j;
        uint v;
        if (k < batch_end && survives(k, v)) values[count++] = v;
    }
    // Inclusive scan of the per-invocation counts (Hillis-Steele over the work group).
    s_scan[l] = count;
    barrier();
    for (uint off = 1u; off < OCCLUSION_GROUP; off <<= 1) {
        uint add = l >= off ? s_scan[l - off] : 0u;
        barrier();
        s_scan[l] += add;
        barrier();
    }
    uint at = seg_base + s_scan[l] - count;
    for (uint j = 0u; j < count; ++j) survivors[at + j] = values[j];
    if (l == OCCLUSION_GROUP - 1u) {
        uint c = 5u * (u_cmd_base + gl_WorkGroupID.x);
        commands[c] = 4u;
        commands[c + 1u] = s_scan[l];
        commands[c + 2u] = 0u;
        commands[c + 3u] = seg_base;
        commands[c + 4u] = 0u;
    }
}
