// Radix sort, block pass step 1 of 3 (pass slot u_slot): each lane counts the digits of its
// block in a private array (llvmpipe keeps it on the stack: gathers, no storage access a key)
// and writes them as its row of hist.
// Twin: splatgl/splatmath/radix.py radix_sort_twin().
#include "lib/radix_block_io.glsl"
#include "lib/radix_block.glsl"

layout(local_size_x = RADIX_BLOCK_LANES) in;
layout(std430, binding = RADIX_BINDING_HIST) writeonly buffer Hist { uvec4 hist[]; };

uniform uint u_slot;

void main() {
    uint lane = gl_GlobalInvocationID.x;
    uint lo, hi;
    block_range(lane, radix_count(), lo, hi);
    uint shift = st_pass[u_slot].w;
    uint h[BLOCK_RADIX];
    for (uint d = 0u; d < BLOCK_RADIX; ++d) h[d] = 0u;
    uint i = lo;
    for (; i + 4u <= hi; i += 4u) {
        uvec4 d = (KEYS4(i) >> shift) & BLOCK_MASK;
        h[d.x] += 1u;
        h[d.y] += 1u;
        h[d.z] += 1u;
        h[d.w] += 1u;
    }
    for (; i < hi; ++i) h[block_digit(KEY1(i), shift)] += 1u;
    uint row = lane * (BLOCK_RADIX / 4u);
    for (uint d = 0u; d < BLOCK_RADIX; d += 4u)
        hist[row + d / 4u] = uvec4(h[d], h[d + 1u], h[d + 2u], h[d + 3u]);
}
