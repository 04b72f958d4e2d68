// Radix sort, block passes, step 1: the OR and the AND of every key (radix_bits.comp's job,
// one contiguous block of keys a lane, 4 keys a load), so the plan can skip the bits all keys
// share.
// Twin: splatgl/splatmath/radix.py radix_passes().
#include "lib/radix_block.glsl"

layout(local_size_x = RADIX_BLOCK_LANES) in;
layout(std430, binding = RADIX_BINDING_KEYS_IN) readonly buffer KeysIn { uvec4 keys_in[]; };

void main() {
    uint lo, hi;
    block_range(gl_GlobalInvocationID.x, radix_count(), lo, hi);
    uvec4 bits_or = uvec4(0u), bits_and = uvec4(~0u);
    uint i = lo;
    for (; i + 4u <= hi; i += 4u) {
        uvec4 k = keys_in[i >> 2];
        bits_or |= k;
        bits_and &= k;
    }
    for (; i < hi; ++i) {
        uint k = keys_in[i >> 2][i & 3u];
        bits_or.x |= k;
        bits_and.x &= k;
    }
    if (lo < hi) {
        atomicOr(st_or, bits_or.x | bits_or.y | bits_or.z | bits_or.w);
        atomicAnd(st_and, bits_and.x & bits_and.y & bits_and.z & bits_and.w);
    }
}
