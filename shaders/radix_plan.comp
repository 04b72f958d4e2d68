// Radix sort, step 2 (one work group): the passes the keys need, written where the passes'
// indirect dispatches read them, so nothing is read back to plan a sort.  A pass sorts by
// RADIX_BITS bits from the lowest bit in which the keys differ; passes beyond the highest such
// bit get no work groups.  The passes alternate between the A and B buffers, so after an odd
// number the copy dispatch brings the result back into A.  Also resets the bits and the digit
// totals for the next sort.
// Twin: splatgl/splatmath/radix.py radix_passes().
#include "lib/radix.glsl"

layout(local_size_x = RADIX_GROUP) in;

void main() {
    uint count = radix_count();
    uint t = gl_LocalInvocationID.x;
    for (uint i = t; i < uint(RADIX_SLOTS) * RADIX; i += uint(RADIX_GROUP)) st_total[i] = 0u;
    if (t != 0u) return;
    uint differ = count < 2u ? 0u : st_or & ~st_and;
    uint lo = 0u, passes = 0u;
    if (differ != 0u) {
        lo = uint(findLSB(differ));
        uint hi = uint(findMSB(differ)) + 1u;
        passes = (hi - lo + uint(RADIX_BITS) - 1u) / uint(RADIX_BITS);
    }
    st_or = 0u;
    st_and = ~0u;
    st_lo = lo;
    st_passes = passes;
    uint tiles = (count + TILE_KEYS - 1u) / TILE_KEYS;  // of the keys there are, not the capacity
    for (uint s = 0u; s < uint(RADIX_SLOTS); ++s) {
        bool on = s < passes;
        st_pass[s] = uvec4(on ? tiles : 0u, 1u, 1u, lo + s * uint(RADIX_BITS));
        st_scan[s] = uvec4(on ? RADIX : 0u, 1u, 1u, 0u);
    }
    st_copy = uvec4((passes & 1u) != 0u ? tiles : 0u, 1u, 1u, 0u);
}
