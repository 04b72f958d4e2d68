// Radix sort, pass step 1 of 3 (pass slot u_slot): each tile's count of each digit, counted in
// shared memory, into hist (digit-major), and added to the pass's digit totals.
// Twin: splatgl/splatmath/radix.py radix_sort_twin().
#include "lib/radix.glsl"

layout(local_size_x = RADIX_GROUP) in;
layout(std430, binding = RADIX_BINDING_KEYS_IN) readonly buffer KeysIn { uint keys_in[]; };
layout(std430, binding = RADIX_BINDING_HIST) writeonly buffer Hist { uint hist[]; };

uniform uint u_slot;  // which pass of the plan this is

#if defined(RADIX_NARROW)
// A narrow group (one CPU SIMD warp, many keys per thread): each thread counts into its own
// column without atomics (llvmpipe's shared atomics cost several times a load), then the
// columns are summed.
shared uint s_count[RADIX * uint(RADIX_GROUP)];  // [d * RADIX_GROUP + t]
#else
shared uint s_count[RADIX];
#endif

void main() {
    uint count = radix_count();
    uint t = gl_LocalInvocationID.x;
    uint tile = gl_WorkGroupID.x;
    for (uint i = t; i < s_count.length(); i += uint(RADIX_GROUP)) s_count[i] = 0u;
    barrier();
    uint shift = st_pass[u_slot].w;
    uint base = tile * TILE_KEYS + t;
    for (uint i = 0u; i < uint(RADIX_ITEMS); ++i) {
        uint idx = base + i * uint(RADIX_GROUP);
        if (idx < count) {
            uint d = radix_digit(keys_in[idx], shift);
#if defined(RADIX_NARROW)
            s_count[d * uint(RADIX_GROUP) + t] += 1u;
#else
            atomicAdd(s_count[d], 1u);
#endif
        }
    }
    barrier();
    for (uint d = t; d < RADIX; d += uint(RADIX_GROUP)) {
#if defined(RADIX_NARROW)
        uint c = 0u;
        for (uint j = 0u; j < uint(RADIX_GROUP); ++j) c += s_count[d * uint(RADIX_GROUP) + j];
#else
        uint c = s_count[d];
#endif
        hist[d * u_tiles + tile] = c;
        if (c != 0u) atomicAdd(st_total[u_slot * RADIX + d], c);
    }
}
