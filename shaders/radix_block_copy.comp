// Radix sort, block passes: after a single pass the sorted keys and values are in B; this
// copies them into A, where every sort leaves its result (the plan gives it no work groups
// otherwise).
// Twin: none (plumbing: a copy of the sorted keys and values).
#include "lib/radix_block.glsl"

layout(local_size_x = RADIX_BLOCK_LANES) in;
layout(std430, binding = RADIX_BINDING_KEYS_IN) readonly buffer KeysIn { uvec4 keys_in[]; };
layout(std430, binding = RADIX_BINDING_VALS_IN) readonly buffer ValsIn { uvec4 vals_in[]; };
layout(std430, binding = RADIX_BINDING_KEYS_OUT) buffer KeysOut { uvec4 keys_out[]; };
layout(std430, binding = RADIX_BINDING_VALS_OUT) buffer ValsOut { uvec4 vals_out[]; };

void main() {
    uint lo, hi;
    block_range(gl_GlobalInvocationID.x, radix_count(), lo, hi);
    uint i = lo;
    for (; i + 4u <= hi; i += 4u) {
        keys_out[i >> 2] = keys_in[i >> 2];
        vals_out[i >> 2] = vals_in[i >> 2];
    }
    for (; i < hi; ++i) {  // the keys past the count stay as they are
        keys_out[i >> 2][i & 3u] = keys_in[i >> 2][i & 3u];
        vals_out[i >> 2][i & 3u] = vals_in[i >> 2][i & 3u];
    }
}
