// Radix sort, pass step 3 of 3: the stable scatter of keys and values by digit.
//
// The tile is cut into RADIX_WARP-wide warps, each owning RADIX_ITEMS * RADIX_WARP consecutive
// keys that it ranks in RADIX_ITEMS rounds of one key per lane (warp-level multi-split): a key's
// rank in its warp is the keys of its digit in the warp's earlier rounds (the per-warp
// histogram s_warp) plus those in lower lanes of its round (the match).  Then, per digit, a scan
// over the warps adds the tile's start for the digit (radix_scan.comp), and each key is written
// at its warp's start + its rank.  Keys are ranked in input order, so equal digits keep it (the
// pass is stable, hence the whole LSD sort).
//
// The match: with GL_KHR_shader_subgroup, RADIX_BITS ballots (RADIX_MATCH_KHR); with
// GL_ARB_shader_ballot, one broadcast per lane (RADIX_MATCH_ARB, for narrow subgroups: CPU
// SIMD lanes); otherwise RADIX_WARP threads exchange their digits through shared memory between
// work-group barriers (the portable path).
// Twin: splatgl/splatmath/radix.py radix_sort_twin().
#if defined(RADIX_MATCH_KHR)
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_ballot : require
#elif defined(RADIX_MATCH_ARB)
#extension GL_ARB_shader_ballot : require
#endif
#include "lib/radix.glsl"

layout(local_size_x = RADIX_GROUP) in;
layout(std430, binding = RADIX_BINDING_KEYS_IN) readonly buffer KeysIn { uint keys_in[]; };
layout(std430, binding = RADIX_BINDING_VALS_IN) readonly buffer ValsIn { uint vals_in[]; };
layout(std430, binding = RADIX_BINDING_KEYS_OUT) writeonly buffer KeysOut { uint keys_out[]; };
layout(std430, binding = RADIX_BINDING_VALS_OUT) writeonly buffer ValsOut { uint vals_out[]; };
layout(std430, binding = RADIX_BINDING_HIST) readonly buffer Hist { uint hist[]; };

uniform uint u_slot;

#ifndef RADIX_WARP  // the subgroup paths define it: the device's subgroup size
#define RADIX_WARP RADIX_PORTABLE_WARP
#endif
#define WARPS (uint(RADIX_GROUP) / uint(RADIX_WARP))
#if defined(RADIX_NARROW)
shared uint s_warp[RADIX];  // [d]: where the next key of digit d goes
#else
// [w * RADIX + d]: warp w's keys of digit d, then their start; then the tile staged in order
shared uint s_warp[max(WARPS * RADIX, TILE_KEYS)];
#endif

#if defined(RADIX_MATCH_KHR)
#define LANE gl_SubgroupInvocationID
#define WARP gl_SubgroupID
// the leader's write of s_warp must follow its peers' reads, and the next round's reads it
#define WARP_SYNC() subgroupMemoryBarrierShared(); subgroupBarrier()
#elif defined(RADIX_MATCH_ARB)
#define LANE gl_SubGroupInvocationARB
#define WARP (gl_LocalInvocationID.x / uint(RADIX_WARP))
#define WARP_SYNC()  // a subgroup runs in lock step: its reads of a round precede its writes
#else
#define LANE (gl_LocalInvocationID.x % uint(RADIX_WARP))
#define WARP (gl_LocalInvocationID.x / uint(RADIX_WARP))
#define WARP_SYNC() barrier()
shared uint s_digit[RADIX_GROUP];
#endif

// ``lower``: lanes of this round below this one with digit d; ``count``: all lanes with d.
void radix_match(uint d, uint lane, uint warp, out uint lower, out uint count) {
#if defined(RADIX_MATCH_KHR)
    uvec4 peers = subgroupBallot(true);
    for (uint b = 0u; b < uint(RADIX_BITS); ++b) {
        bool set = ((d >> b) & 1u) != 0u;
        uvec4 m = subgroupBallot(set);
        peers &= set ? m : ~m;
    }
    lower = subgroupBallotBitCount(peers & gl_SubgroupLtMask);
    count = subgroupBallotBitCount(peers);
#elif defined(RADIX_MATCH_ARB)
    lower = 0u;
    count = 0u;
    for (uint j = 0u; j < uint(RADIX_WARP); ++j) {
        bool same = uint(readInvocationARB(int(d), j)) == d;  // int: glslang has no uint form
        count += same ? 1u : 0u;
        lower += (same && j < lane) ? 1u : 0u;
    }
#else
    s_digit[gl_LocalInvocationID.x] = d;
    barrier();
    uint first = warp * uint(RADIX_WARP);
    lower = 0u;
    count = 0u;
    for (uint j = 0u; j < uint(RADIX_WARP); ++j) {
        bool same = s_digit[first + j] == d;
        count += same ? 1u : 0u;
        lower += (same && j < lane) ? 1u : 0u;
    }
#endif
}

#if defined(RADIX_NARROW)  // RADIX_GROUP == RADIX_WARP
// One warp per group (narrow subgroups: a CPU's SIMD lanes, with many keys per lane): the warp's
// counts are the tile's, which the upsweep counted and the scan turned into starts, so each
// round writes its keys at once; no per-warp counting, no second loop.
void main() {
    uint n_keys = radix_count();
    uint t = gl_LocalInvocationID.x;
    uint tile = gl_WorkGroupID.x;
    uint lane = LANE;
    for (uint d = t; d < RADIX; d += uint(RADIX_GROUP)) s_warp[d] = hist[d * u_tiles + tile];
    barrier();
    uint shift = st_pass[u_slot].w;
    uint seg = tile * TILE_KEYS + lane;
    for (uint i = 0u; i < uint(RADIX_ITEMS); ++i) {
        uint idx = seg + i * uint(RADIX_WARP);
        uint key = idx < n_keys ? keys_in[idx] : ~0u;  // past the end: after every real key
        uint d = radix_digit(key, shift);
        uint lower, count;
        radix_match(d, lane, 0u, lower, count);
        uint before = s_warp[d];
        WARP_SYNC();
        if (lower == 0u) s_warp[d] = before + count;
#if defined(RADIX_MATCH_KHR)
        WARP_SYNC();
#endif
        if (idx < n_keys) {
            keys_out[before + lower] = key;
            vals_out[before + lower] = vals_in[idx];
        }
    }
}
#else
// Wide groups (GPUs): rank every key of the tile first (per-warp counts in s_warp), then place
// the tile sorted by digit in shared memory and write it out in order, so neighbouring threads
// write neighbouring addresses (coalesced), keys first, then values through the same memory.
shared uint s_shift[RADIX];  // per digit: its tile start in the output minus its start here
shared uint s_scan[RADIX_GROUP];
#define STAGE_ITEMS ((TILE_KEYS + uint(RADIX_GROUP) - 1u) / uint(RADIX_GROUP))

void main() {
    uint n_keys = radix_count();
    uint t = gl_LocalInvocationID.x;
    uint tile = gl_WorkGroupID.x;
    uint lane = LANE, warp = WARP;
    for (uint i = t; i < WARPS * RADIX; i += uint(RADIX_GROUP)) s_warp[i] = 0u;
    barrier();
    uint shift = st_pass[u_slot].w;
    uint seg = tile * TILE_KEYS + warp * uint(RADIX_ITEMS) * uint(RADIX_WARP) + lane;
    uint keys[RADIX_ITEMS];
    uint rank[RADIX_ITEMS];
    for (uint i = 0u; i < uint(RADIX_ITEMS); ++i) {
        uint idx = seg + i * uint(RADIX_WARP);
        // Past the end: all ones, ranked after every real key of its warp (only later keys
        // are past the end too), never written.
        uint key = idx < n_keys ? keys_in[idx] : ~0u;
        uint d = radix_digit(key, shift);
        uint lower, count;
        radix_match(d, lane, warp, lower, count);
        uint at = warp * RADIX + d;
        uint before = s_warp[at];
        WARP_SYNC();
        if (lower == 0u) s_warp[at] = before + count;
#if defined(RADIX_MATCH_KHR)
        WARP_SYNC();
#endif
        keys[i] = key;
        rank[i] = before + lower;
    }
    barrier();
    // Per digit: the warps' starts within the digit's run, and the run's length.
    uint runs[(RADIX + uint(RADIX_GROUP) - 1u) / uint(RADIX_GROUP)];
    uint sum = 0u;
    for (uint d = t, k = 0u; d < RADIX; d += uint(RADIX_GROUP), ++k) {
        uint run = 0u;
        for (uint w = 0u; w < WARPS; ++w) {
            uint c = s_warp[w * RADIX + d];
            s_warp[w * RADIX + d] = run;
            run += c;
        }
        runs[k] = run;
        sum += run;
    }
    // Where each digit's run goes in the staged tile: after the runs of the threads before
    // (a scan of the threads' sums) and of this thread's earlier digits.  The runs need not be
    // in digit order here, only apart: s_shift maps each back to its place in the output.
    s_scan[t] = sum;
    barrier();
    for (uint off = 1u; off < uint(RADIX_GROUP); off <<= 1u) {
        uint add = t >= off ? s_scan[t - off] : 0u;
        barrier();
        s_scan[t] += add;
        barrier();
    }
    barrier();
    uint start = s_scan[t] - sum;
    for (uint d = t, k = 0u; d < RADIX; d += uint(RADIX_GROUP), ++k) {
        for (uint w = 0u; w < WARPS; ++w) s_warp[w * RADIX + d] += start;
        s_shift[d] = hist[d * u_tiles + tile] - start;
        start += runs[k];
    }
    barrier();
    for (uint i = 0u; i < uint(RADIX_ITEMS); ++i)
        rank[i] += s_warp[warp * RADIX + radix_digit(keys[i], shift)];  // place in the tile
    barrier();  // s_warp is the staging memory from here
    uint first = tile * TILE_KEYS;
    uint here = min(n_keys - first, TILE_KEYS);  // keys in this tile
    for (uint i = 0u; i < uint(RADIX_ITEMS); ++i)
        if (seg + i * uint(RADIX_WARP) < n_keys) s_warp[rank[i]] = keys[i];
    barrier();
    uint out_at[STAGE_ITEMS];
    for (uint m = 0u; m < STAGE_ITEMS; ++m) {
        uint j = t + m * uint(RADIX_GROUP);
        if (j < here) {
            uint key = s_warp[j];
            out_at[m] = s_shift[radix_digit(key, shift)] + j;
            keys_out[out_at[m]] = key;
        }
    }
    barrier();
    for (uint i = 0u; i < uint(RADIX_ITEMS); ++i) {
        uint idx = seg + i * uint(RADIX_WARP);
        if (idx < n_keys) s_warp[rank[i]] = vals_in[idx];
    }
    barrier();
    for (uint m = 0u; m < STAGE_ITEMS; ++m) {
        uint j = t + m * uint(RADIX_GROUP);
        if (j < here) vals_out[out_at[m]] = s_warp[j];
    }
}
#endif
