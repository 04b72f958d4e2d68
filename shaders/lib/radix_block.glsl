// The radix sort's block passes (software devices; splatgl/gl/radix_block.py has the design).
// RADIX_BLOCK_GROUPS groups of RADIX_BLOCK_LANES invocations: invocation (lane) l of the
// BLOCK_LANES owns the l-th contiguous block of the keys, a multiple of 4 keys long (uvec4
// loads: one storage access brings 4 keys), and works through it alone: no barriers, no
// shared memory, no subgroup operations.  Its digit counts are a row of hist (lane-major,
// hist[l * BLOCK_RADIX + d]), which radix_block_scan.comp turns into where its first key of
// each digit goes.
// Twin: splatgl/splatmath/radix.py radix_sort_twin(), radix_passes().
#include "lib/radix.glsl"

#define BLOCK_RADIX (1u << RADIX_BLOCK_BITS)
#define BLOCK_MASK (BLOCK_RADIX - 1u)
#define BLOCK_LANES (uint(RADIX_BLOCK_GROUPS) * uint(RADIX_BLOCK_LANES))

// [lo, hi): the keys lane ``lane`` owns of ``count``.
void block_range(uint lane, uint count, out uint lo, out uint hi) {
    uint per = ((count + BLOCK_LANES - 1u) / BLOCK_LANES + 3u) & ~3u;
    lo = min(lane * per, count);
    hi = min(lo + per, count);
}

uint block_digit(uint key, uint shift) { return (key >> shift) & BLOCK_MASK; }
