// Radix sort, block passes: after a single pass the sorted keys and values are in B; this
// copies them into A, where every sort leaves its result (the plan gives it no work groups
// otherwise).
// Twin: none (plumbing: a copy of the sorted keys and values).
#include "lib/radix_block_io.glsl"
#include "lib/radix_block.glsl"

layout(local_size_x = RADIX_BLOCK_LANES) in;

void main() {
    uint lo, hi;
    block_range(gl_GlobalInvocationID.x, radix_count(), lo, hi);
    uint i = lo;
    for (; i + 4u <= hi; i += 4u) {
        uvec4 k, v;
        LOAD4(i, k, v)
        STORE1(i, k.x, v.x);
        STORE1(i + 1u, k.y, v.y);
        STORE1(i + 2u, k.z, v.z);
        STORE1(i + 3u, k.w, v.w);
    }
    for (; i < hi; ++i) {  // the keys past the count stay as they are
        uint k, v;
        LOAD1(i, k, v)
        STORE1(i, k, v);
    }
}
