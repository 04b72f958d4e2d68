// Shared by the radix sort passes (splatgl/gl/radix_sort.py).
// Twin: splatgl/gl/radix_sort.py radix_sort_twin().
// One work group of RADIX_GROUP threads owns a tile of RADIX_GROUP * RADIX_ITEMS keys; thread t
// owns the RADIX_ITEMS consecutive keys from tile * TILE_KEYS + t * RADIX_ITEMS.  hist holds,
// digit-major, each tile's count of each digit: hist[d * u_tiles + tile].
#define RADIX (1u << RADIX_BITS)
#define TILE_KEYS (uint(RADIX_GROUP) * uint(RADIX_ITEMS))

uniform uint u_count;  // keys to sort
uniform uint u_shift;  // bit position of this pass's digit
uniform uint u_tiles;  // number of tiles, ceil(u_count / TILE_KEYS)

uint radix_digit(uint key) { return (key >> u_shift) & (RADIX - 1u); }
