// The block passes' keys and values in and out (radix_block_count/scatter/copy.comp).  A holds
// keys and values apart (what callers write and read); between passes they travel as pairs,
// one uvec2 (key, value) a key, where RADIX_BLOCK_SRC_PAIRS / RADIX_BLOCK_DST_PAIRS say so: one
// storage access writes both (llvmpipe loops over the lanes once per access: a uvec2 write
// costs about 0.7 of two uint writes, and 0.8 of a uint64 one).
//   LOAD4(i, k, v): keys and values i..i+3 (i even) into uvec4 k, v
//   LOAD1(i, k, v): key and value i;  KEYS4(i), KEY1(i): the keys alone
//   STORE1(o, k, v): key and value at o
// Include it first.
// Twin: none (storage accessors of the block passes; the sort's twin is named in radix_block.glsl).
#if defined(RADIX_BLOCK_SRC_PAIRS)
layout(std430, binding = RADIX_BINDING_KEYS_IN) readonly buffer PairsIn { uvec4 pairs_in[]; };
#define LOAD4(i, k, v) { uvec4 a_ = pairs_in[(i) >> 1], b_ = pairs_in[((i) >> 1) + 1u]; \
                         k = uvec4(a_.xz, b_.xz); v = uvec4(a_.yw, b_.yw); }
#define LOAD1(i, k, v) { uvec4 q_ = pairs_in[(i) >> 1]; k = ((i) & 1u) == 0u ? q_.x : q_.z; \
                         v = ((i) & 1u) == 0u ? q_.y : q_.w; }
#define KEYS4(i) uvec4(pairs_in[(i) >> 1].xz, pairs_in[((i) >> 1) + 1u].xz)
#define KEY1(i) (((i) & 1u) == 0u ? pairs_in[(i) >> 1].x : pairs_in[(i) >> 1].z)
#else
layout(std430, binding = RADIX_BINDING_KEYS_IN) readonly buffer KeysIn { uvec4 keys_in[]; };
layout(std430, binding = RADIX_BINDING_VALS_IN) readonly buffer ValsIn { uvec4 vals_in[]; };
#define LOAD4(i, k, v) { k = keys_in[(i) >> 2]; v = vals_in[(i) >> 2]; }
#define LOAD1(i, k, v) { k = keys_in[(i) >> 2][(i) & 3u]; v = vals_in[(i) >> 2][(i) & 3u]; }
#define KEYS4(i) keys_in[(i) >> 2]
#define KEY1(i) keys_in[(i) >> 2][(i) & 3u]
#endif

#if defined(RADIX_BLOCK_DST_PAIRS)
layout(std430, binding = RADIX_BINDING_KEYS_OUT) writeonly buffer PairsOut { uvec2 pairs_out[]; };
#define STORE1(o, k, v) pairs_out[o] = uvec2(k, v)
#else
layout(std430, binding = RADIX_BINDING_KEYS_OUT) buffer KeysOut { uint keys_out[]; };
layout(std430, binding = RADIX_BINDING_VALS_OUT) buffer ValsOut { uint vals_out[]; };
#define STORE1(o, k, v) { keys_out[o] = k; vals_out[o] = v; }
#endif
