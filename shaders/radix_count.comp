// Radix sort, pass step 1 of 3: each tile's count of each digit, into hist (digit-major).
// Twin: splatgl/gl/radix_sort.py radix_sort_twin().
#include "lib/radix.glsl"

layout(local_size_x = RADIX_GROUP) in;
layout(std430, binding = RADIX_BINDING_KEYS_IN) readonly buffer KeysIn { uint keys_in[]; };
layout(std430, binding = RADIX_BINDING_HIST) writeonly buffer Hist { uint hist[]; };

shared uint s_count[RADIX];

void main() {
    uint t = gl_LocalInvocationID.x;
    uint tile = gl_WorkGroupID.x;
    if (t < RADIX) s_count[t] = 0u;
    barrier();
    uint base = tile * TILE_KEYS + t * uint(RADIX_ITEMS);
    for (uint i = 0u; i < uint(RADIX_ITEMS); ++i) {
        uint idx = base + i;
        if (idx < u_count) atomicAdd(s_count[radix_digit(keys_in[idx])], 1u);
    }
    barrier();
    if (t < RADIX) hist[t * u_tiles + tile] = s_count[t];
}
