// Radix sort, last step: after an odd number of passes the sorted keys and values are in the
// B buffers; this copies them into A, where every sort leaves its result (radix_plan.comp
// gives it no work groups after an even number).
// Twin: none (plumbing: a copy of the sorted keys and values).
#include "lib/radix.glsl"

layout(local_size_x = RADIX_GROUP) in;
layout(std430, binding = RADIX_BINDING_KEYS_IN) readonly buffer KeysIn { uint keys_in[]; };
layout(std430, binding = RADIX_BINDING_VALS_IN) readonly buffer ValsIn { uint vals_in[]; };
layout(std430, binding = RADIX_BINDING_KEYS_OUT) writeonly buffer KeysOut { uint keys_out[]; };
layout(std430, binding = RADIX_BINDING_VALS_OUT) writeonly buffer ValsOut { uint vals_out[]; };

void main() {
    uint count = radix_count();
    uint base = gl_WorkGroupID.x * TILE_KEYS + gl_LocalInvocationID.x;
    for (uint i = 0u; i < uint(RADIX_ITEMS); ++i) {
        uint idx = base + i * uint(RADIX_GROUP);
        if (idx < count) {
            keys_out[idx] = keys_in[idx];
            vals_out[idx] = vals_in[idx];
        }
    }
}
