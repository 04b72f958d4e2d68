// Radix sort, step 1: the OR and the AND of every key, so radix_plan.comp can skip the bits all
// keys share.
// Twin: splatgl/splatmath/radix.py radix_passes().
#include "lib/radix.glsl"

layout(local_size_x = RADIX_GROUP) in;
layout(std430, binding = RADIX_BINDING_KEYS_IN) readonly buffer KeysIn { uint keys_in[]; };

shared uint s_or, s_and;

void main() {
    uint count = radix_count();
    uint t = gl_LocalInvocationID.x;
    if (t == 0u) { s_or = 0u; s_and = ~0u; }
    barrier();
    uint base = gl_WorkGroupID.x * TILE_KEYS + t;
    uint bits_or = 0u, bits_and = ~0u;
    for (uint i = 0u; i < uint(RADIX_ITEMS); ++i) {
        uint idx = base + i * uint(RADIX_GROUP);
        if (idx < count) {
            uint key = keys_in[idx];
            bits_or |= key;
            bits_and &= key;
        }
    }
    atomicOr(s_or, bits_or);
    atomicAnd(s_and, bits_and);
    barrier();
    if (t == 0u) {
        atomicOr(st_or, s_or);
        atomicAnd(st_and, s_and);
    }
}
