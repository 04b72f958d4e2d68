// Radix sort, block pass step 3 of 3: each lane walks its block in order and writes every key
// and value at its digit's next place (its start from radix_block_scan.comp, kept in a
// private array).  A lane's keys of one digit keep their order and land after the same digit's
// keys of the lanes before it: the pass is stable by construction, hence the whole LSD sort.
// Twin: splatgl/splatmath/radix.py radix_sort_twin().
#include "lib/radix_block_io.glsl"
#include "lib/radix_block.glsl"

layout(local_size_x = RADIX_BLOCK_LANES) in;
layout(std430, binding = RADIX_BINDING_HIST) readonly buffer Hist { uvec4 hist[]; };

uniform uint u_slot;

void main() {
    uint lane = gl_GlobalInvocationID.x;
    uint lo, hi;
    block_range(lane, radix_count(), lo, hi);
    uint shift = st_pass[u_slot].w;
    uint h[BLOCK_RADIX];
    uint row = lane * (BLOCK_RADIX / 4u), starts = BLOCK_LANES * (BLOCK_RADIX / 4u);
    for (uint d = 0u; d < BLOCK_RADIX; d += 4u) {
        uvec4 at = hist[row + d / 4u] + hist[starts + d / 4u];
        h[d] = at.x;
        h[d + 1u] = at.y;
        h[d + 2u] = at.z;
        h[d + 3u] = at.w;
    }
#define PLACE(key, value) { uint d_ = block_digit(key, shift); uint o_ = h[d_]; h[d_] = o_ + 1u; \
                            STORE1(o_, key, value); }
    uint i = lo;
    for (; i + 4u <= hi; i += 4u) {
        uvec4 k, v;
        LOAD4(i, k, v)
        PLACE(k.x, v.x)
        PLACE(k.y, v.y)
        PLACE(k.z, v.z)
        PLACE(k.w, v.w)
    }
    for (; i < hi; ++i) {
        uint k, v;
        LOAD1(i, k, v)
        PLACE(k, v)
    }
}
