// Radix sort, step 2 (one work group): the passes the keys need, written where the passes'
// indirect dispatches read them, so nothing is read back to plan a sort.  A pass sorts by
// PLAN_BITS bits from the lowest bit in which the keys differ; passes beyond the highest such
// bit get no work groups.  Also resets the bits (and the digit totals) for the next sort.
//
// Work-group passes (GPUs, PLAN_BITS = RADIX_BITS): they alternate between the A and B
// buffers, so after an odd number the copy dispatch brings the result back into A.
// Block passes (RADIX_BLOCK, software devices, PLAN_BITS = RADIX_BLOCK_BITS): pass s reads A
// (s = 0) or what pass s - 1 wrote, and writes B (s even) or C (s odd) (st_mid), except the last
// of several passes, which writes A (st_last); a single pass writes B and the copy brings it
// into A.
// Twin: splatgl/splatmath/radix.py radix_passes().
#include "lib/radix.glsl"

#if defined(RADIX_BLOCK)
#define PLAN_BITS RADIX_BLOCK_BITS
#else
#define PLAN_BITS RADIX_BITS
#endif

layout(local_size_x = RADIX_GROUP) in;

void main() {
    uint count = radix_count();
    uint t = gl_LocalInvocationID.x;
#if !defined(RADIX_BLOCK)
    for (uint i = t; i < uint(RADIX_SLOTS) * RADIX; i += uint(RADIX_GROUP)) st_total[i] = 0u;
#endif
    if (t != 0u) return;
    uint differ = count < 2u ? 0u : st_or & ~st_and;
    uint lo = 0u, passes = 0u;
    if (differ != 0u) {
        lo = uint(findLSB(differ));
        uint hi = uint(findMSB(differ)) + 1u;
        passes = (hi - lo + uint(PLAN_BITS) - 1u) / uint(PLAN_BITS);
    }
    st_or = 0u;
    st_and = ~0u;
    st_lo = lo;
    st_passes = passes;
#if defined(RADIX_BLOCK)
    uint groups = uint(RADIX_BLOCK_GROUPS);  // every pass: each lane owns a block of keys
    for (uint s = 0u; s < uint(RADIX_SLOTS); ++s) {
        bool on = s < passes;
        bool last = on && s + 1u == passes && passes > 1u;
        st_pass[s] = uvec4(on ? groups : 0u, 1u, 1u, lo + s * uint(PLAN_BITS));
        st_scan[s] = uvec4(on ? 1u : 0u, 1u, 1u, 0u);
        st_mid[s] = uvec4(on && !last ? groups : 0u, 1u, 1u, 0u);
        st_last[s] = uvec4(last ? groups : 0u, 1u, 1u, 0u);
    }
    st_copy = uvec4(passes == 1u ? groups : 0u, 1u, 1u, 0u);
#else
    uint tiles = (count + TILE_KEYS - 1u) / TILE_KEYS;  // of the keys there are, not the capacity
    for (uint s = 0u; s < uint(RADIX_SLOTS); ++s) {
        bool on = s < passes;
        st_pass[s] = uvec4(on ? tiles : 0u, 1u, 1u, lo + s * uint(PLAN_BITS));
        st_scan[s] = uvec4(on ? RADIX : 0u, 1u, 1u, 0u);
    }
    st_copy = uvec4((passes & 1u) != 0u ? tiles : 0u, 1u, 1u, 0u);
#endif
}
