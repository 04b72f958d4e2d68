// Radix sort, pass step 2 of 3: exclusive prefix sum of hist in place (one work group).
// After it, hist[d * u_tiles + tile] is where tile's first key of digit d goes.
// Twin: splatgl/gl/radix_sort.py radix_sort_twin().
#include "lib/radix.glsl"

layout(local_size_x = RADIX_GROUP) in;
layout(std430, binding = RADIX_BINDING_HIST) buffer Hist { uint hist[]; };

shared uint s_part[RADIX_GROUP];

void main() {
    uint t = gl_LocalInvocationID.x;
    uint total = RADIX * u_tiles;
    uint seg = (total + uint(RADIX_GROUP) - 1u) / uint(RADIX_GROUP);
    uint lo = min(t * seg, total), hi = min(lo + seg, total);
    uint sum = 0u;
    for (uint i = lo; i < hi; ++i) sum += hist[i];
    s_part[t] = sum;
    barrier();
    // Hillis-Steele inclusive scan of the segment sums
    for (uint off = 1u; off < uint(RADIX_GROUP); off <<= 1u) {
        uint add = t >= off ? s_part[t - off] : 0u;
        barrier();
        s_part[t] += add;
        barrier();
    }
    uint run = s_part[t] - sum;
    for (uint i = lo; i < hi; ++i) {
        uint v = hist[i];
        hist[i] = run;
        run += v;
    }
}
