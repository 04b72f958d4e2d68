// Radix sort, block pass step 2 of 3 (one work group): the lanes' digit counts (hist, a row a
// lane) become, in place, where each lane's first key of each digit goes among the keys of
// that digit (an exclusive scan down each digit's column: lanes in block order), and the
// digit starts (the keys of all smaller digits) go after the rows, at hist[BLOCK_LANES *
// BLOCK_RADIX + d].  In digit-major order, (digit, lane), this is the classic CPU parallel
// radix sort's one scan.
// Twin: splatgl/splatmath/radix.py radix_sort_twin().
#include "lib/radix_block.glsl"

layout(local_size_x = RADIX_BLOCK_SCAN_GROUP) in;
layout(std430, binding = RADIX_BINDING_HIST) buffer Hist { uint hist[]; };

shared uint s_total[BLOCK_RADIX];

void main() {
    uint t = gl_LocalInvocationID.x;
    for (uint d = t; d < BLOCK_RADIX; d += uint(RADIX_BLOCK_SCAN_GROUP)) {
        uint run = 0u;
        for (uint l = 0u; l < BLOCK_LANES; ++l) {
            uint at = l * BLOCK_RADIX + d;
            uint c = hist[at];
            hist[at] = run;
            run += c;
        }
        s_total[d] = run;
    }
    barrier();
    if (t == 0u) {
        uint run = 0u;
        for (uint d = 0u; d < BLOCK_RADIX; ++d) {
            uint c = s_total[d];
            hist[BLOCK_LANES * BLOCK_RADIX + d] = run;
            run += c;
        }
    }
}
