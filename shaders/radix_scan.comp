// Radix sort, pass step 2 of 3: work group d turns its digit's row of hist into where each
// tile's first key of digit d goes: the keys of all smaller digits (from the pass's digit
// totals) plus the exclusive prefix over the tiles before it.  Reduce-then-scan, with O(tiles)
// work: each thread sums a run of consecutive tiles, one thread scans the RADIX_SCAN_GROUP run
// sums, each thread rescans its run.
// Twin: splatgl/splatmath/radix.py radix_sort_twin().
#include "lib/radix.glsl"

layout(local_size_x = RADIX_SCAN_GROUP) in;
layout(std430, binding = RADIX_BINDING_HIST) buffer Hist { uint hist[]; };

uniform uint u_slot;

shared uint s_run[RADIX_SCAN_GROUP];    // each thread's run sum, then its run's start
shared uint s_below[RADIX_SCAN_GROUP];  // each thread's share of the smaller digits' keys

void main() {
    uint t = gl_LocalInvocationID.x;
    uint d = gl_WorkGroupID.x;
    uint per = (u_tiles + uint(RADIX_SCAN_GROUP) - 1u) / uint(RADIX_SCAN_GROUP);
    uint lo = min(t * per, u_tiles), hi = min(lo + per, u_tiles);
    uint row = d * u_tiles;
    uint sum = 0u;
    for (uint p = lo; p < hi; ++p) sum += hist[row + p];
    uint below = 0u;
    for (uint e = t; e < d; e += uint(RADIX_SCAN_GROUP)) below += st_total[u_slot * RADIX + e];
    s_run[t] = sum;
    s_below[t] = below;
    barrier();
    if (t == 0u) {
        uint run = 0u;
        for (uint i = 0u; i < uint(RADIX_SCAN_GROUP); ++i) run += s_below[i];
        for (uint i = 0u; i < uint(RADIX_SCAN_GROUP); ++i) {
            uint v = s_run[i];
            s_run[i] = run;
            run += v;
        }
    }
    barrier();
    uint run = s_run[t];
    for (uint p = lo; p < hi; ++p) {
        uint v = hist[row + p];
        hist[row + p] = run;
        run += v;
    }
}
