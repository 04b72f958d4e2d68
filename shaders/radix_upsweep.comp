// Radix sort, pass step 1 of 3 (pass slot u_slot): each tile's count of each digit, counted in
// shared memory, into hist (digit-major), and added to the pass's digit totals.
// Twin: splatgl/gl/radix_sort.py radix_sort_twin().
#include "lib/radix.glsl"

layout(local_size_x = RADIX_GROUP) in;
layout(std430, binding = RADIX_BINDING_KEYS_IN) readonly buffer KeysIn { uint keys_in[]; };
layout(std430, binding = RADIX_BINDING_HIST) writeonly buffer Hist { uint hist[]; };

uniform uint u_slot;  // which pass of the plan this is

shared uint s_count[RADIX];

void main() {
    uint t = gl_LocalInvocationID.x;
    uint tile = gl_WorkGroupID.x;
    for (uint d = t; d < RADIX; d += uint(RADIX_GROUP)) s_count[d] = 0u;
    barrier();
    uint shift = st_pass[u_slot].w;
    uint base = tile * TILE_KEYS + t;
    for (uint i = 0u; i < uint(RADIX_ITEMS); ++i) {
        uint idx = base + i * uint(RADIX_GROUP);
        if (idx < u_count) atomicAdd(s_count[radix_digit(keys_in[idx], shift)], 1u);
    }
    barrier();
    for (uint d = t; d < RADIX; d += uint(RADIX_GROUP)) {
        uint c = s_count[d];
        hist[d * u_tiles + tile] = c;
        if (c != 0u) atomicAdd(st_total[u_slot * RADIX + d], c);
    }
}
