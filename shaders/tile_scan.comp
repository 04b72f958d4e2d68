// Tile renderer, stage 2 "scan" of the device order (--sort gpu): the exclusive prefix sum of
// tiles_touched into tile_offsets, reduce-then-scan (as radix_scan.comp): u_stage 0, one group
// per block of TILE_SCAN_GROUP * TILE_SCAN_ITEMS splats, sums its block (and its largest count)
// into scan_blocks; u_stage 1, one group, scans the block sums and writes the frame's state: the
// total, the overflow flag (total above u_capacity keys), the count the sorter reads and the
// indirect dispatches sized from them (emit chunks, the key passes); u_stage 2 rescans each
// block from its start.  Nothing is read back (splatgl/renderers/tile_device.py).
// DEVICE_PRESORT: the splats are taken in depth order (splat_order), so tile_offsets[k] is
// where the k-th nearest splat's keys start.
// Twin: splatgl/renderers/tile_device.py scan_twin().
#define DEVICE_SORT 1
#define TILE_STATE 1
#define TILE_SCAN_BLOCKS 1
#define TILE_NO_KEYS 1
#ifdef DEVICE_PRESORT
#define TILE_SPLAT_ORDER 1
#endif
#include "lib/tile_common.glsl"

layout(local_size_x = TILE_SCAN_GROUP) in;

uniform uint u_stage;
uniform uint u_count;          // splats N
uniform uint u_blocks;         // blocks of the scan: ceil(N / block)
uniform uint u_capacity;       // keys the key buffers hold
uniform uint u_emit_slots;     // emit dispatches (TILE_EMIT_CHUNK keys of each splat each)
uniform uvec2 u_splat_groups;  // an emit dispatch's groups (splat_groups(N))

shared uint s_sum[TILE_SCAN_GROUP];
shared uint s_max[TILE_SCAN_GROUP];
#define BLOCK (uint(TILE_SCAN_GROUP) * uint(TILE_SCAN_ITEMS))

uint touched_at(uint k) {
#ifdef DEVICE_PRESORT
    return tiles_touched[splat_order[k]];
#else
    return tiles_touched[k];
#endif
}

void scan_blocks_stage(uint t) {
    uint per = (u_blocks + uint(TILE_SCAN_GROUP) - 1u) / uint(TILE_SCAN_GROUP);
    uint lo = min(t * per, u_blocks), hi = min(lo + per, u_blocks);
    uint sum = 0u, most = 0u;
    for (uint b = lo; b < hi; ++b) {
        sum += scan_blocks[b].x;
        most = max(most, scan_blocks[b].y);
    }
    s_sum[t] = sum;
    s_max[t] = most;
    barrier();
    if (t == 0u) {
        uint run = 0u;
        for (uint j = 0u; j < uint(TILE_SCAN_GROUP); ++j) {
            uint v = s_sum[j];
            s_sum[j] = run;
            run += v;
            most = max(most, s_max[j]);
        }
        bool over = run > u_capacity;
        ts_total = run;
        ts_overflow = over ? 1u : 0u;
        ts_sort_count = over ? 0u : run;
        ts_max_touched = most;
        ts_key_args = over || run == 0u ? uvec4(0u) : splat_args(run);
        for (uint c = 0u; c < u_emit_slots; ++c)
            ts_args[c] = !over && most > c * uint(TILE_EMIT_CHUNK)
                ? uvec4(u_splat_groups, 1u, 0u) : uvec4(0u);
    }
    barrier();
    uint run = s_sum[t];
    for (uint b = lo; b < hi; ++b) {
        uint v = scan_blocks[b].x;
        scan_blocks[b].x = run;
        run += v;
    }
}

void main() {
    uint t = gl_LocalInvocationID.x;
    if (u_stage == 1u) {
        scan_blocks_stage(t);
        return;
    }
    uint block = gl_WorkGroupID.x;
    uint first = block * BLOCK + t * uint(TILE_SCAN_ITEMS);
    uint sum = 0u, most = 0u;
    for (uint i = 0u; i < uint(TILE_SCAN_ITEMS); ++i) {
        uint idx = first + i;
        if (idx < u_count) {
            uint c = touched_at(idx);
            sum += c;
            most = max(most, c);
        }
    }
    s_sum[t] = sum;
    s_max[t] = most;
    barrier();
    if (u_stage == 0u) {
        if (t == 0u) {
            uint total = 0u;
            for (uint j = 0u; j < uint(TILE_SCAN_GROUP); ++j) {
                total += s_sum[j];
                most = max(most, s_max[j]);
            }
            scan_blocks[block] = uvec2(total, most);
        }
        return;
    }
    if (t == 0u) {  // u_stage 2: each thread's start within the block
        uint run = 0u;
        for (uint j = 0u; j < uint(TILE_SCAN_GROUP); ++j) {
            uint v = s_sum[j];
            s_sum[j] = run;
            run += v;
        }
    }
    barrier();
    uint run = scan_blocks[block].x + s_sum[t];
    for (uint i = 0u; i < uint(TILE_SCAN_ITEMS); ++i) {
        uint idx = first + i;
        if (idx < u_count) {
            tile_offsets[idx] = run;
            run += touched_at(idx);
        }
    }
}
