// Shared by the radix sort's dispatches (splatgl/gl/radix_sort.py; the design is in its module
// doc).
// Twin: splatgl/splatmath/radix.py radix_sort_twin().
//
// A work group of RADIX_GROUP threads owns a tile of TILE_KEYS = RADIX_GROUP * RADIX_ITEMS keys
// per pass.  hist holds, digit-major, each tile's count of each digit, hist[d * u_tiles + tile],
// which radix_scan.comp turns into where the tile's first key of digit d goes.  The state block
// carries the key bits seen (radix_bits.comp), the plan (radix_plan.comp): each pass slot's
// dispatch size and digit shift, read by glDispatchComputeIndirect and the passes, and each
// slot's digit totals (radix_upsweep.comp adds them, radix_scan.comp reads them).
#define RADIX (1u << RADIX_BITS)
#define RADIX_MASK (RADIX - 1u)
#define RADIX_SLOTS (32 / RADIX_BITS)
#define TILE_KEYS (uint(RADIX_GROUP) * uint(RADIX_ITEMS))

uniform uint u_tiles;     // tiles the buffers hold (the capacity / TILE_KEYS, rounded up): hist's row
uniform uint u_capacity;  // keys the buffers hold

layout(std430, binding = RADIX_BINDING_STATE) coherent buffer RadixState {
    uint st_or;       // OR of every key (radix_bits.comp; radix_plan.comp resets it to 0)
    uint st_and;      // AND of every key (reset to ~0)
    uint st_lo;       // lowest bit that differs between keys: the first pass's shift
    uint st_passes;   // passes the keys need: ceil((highest differing bit + 1 - st_lo) / RADIX_BITS)
    uint st_count;    // keys to sort: written by the host, or copied from a device buffer
    uint st_pad0, st_pad1, st_pad2;
    uvec4 st_pass[RADIX_SLOTS];  // xyz: groups of pass s (u_tiles, or 0 to skip it); w: its shift
    uvec4 st_scan[RADIX_SLOTS];  // xyz: groups of pass s's scan (RADIX or 0)
    uvec4 st_copy;               // xyz: groups of the final copy (u_tiles when st_passes is odd)
    // The block passes (radix_block_*.comp, software devices) only: pass s's scatter into the
    // next pass's buffers (st_mid) or, as the last of several passes, into A (st_last).
    uvec4 st_mid[RADIX_SLOTS];
    uvec4 st_last[RADIX_SLOTS];
    uint st_total[RADIX_SLOTS * RADIX];  // keys of each digit in pass s: [s * RADIX + d]
};

// Keys this sort covers: st_count, at most the buffers' capacity (a device-side count that
// overflowed its buffer sorts what the buffers hold).
uint radix_count() { return min(st_count, u_capacity); }

uint radix_digit(uint key, uint shift) { return (key >> shift) & RADIX_MASK; }
