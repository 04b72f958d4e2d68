// The block passes' keys and values in and out (radix_block_count/scatter/copy.comp).  A holds
// keys and values apart (what callers write and read); between passes they travel as pairs,
// one uint64 a key (low half) and its value (high half), where RADIX_BLOCK_SRC_PAIRS /
// RADIX_BLOCK_DST_PAIRS say so: one storage access writes both (llvmpipe pays per access and
// component, so a pass's scattered writes cost about half).
//   LOAD4(i, k, v): keys and values i..i+3 (i a multiple of 4) into uvec4 k, v
//   LOAD1(i, k, v): key and value i;  KEYS4(i), KEY1(i): the keys alone
//   STORE1(o, k, v): key and value at o
// Include it first (its #extension line must precede any code).
// Twin: none (storage accessors of the block passes; the sort's twin is named in radix_block.glsl).
#if defined(RADIX_BLOCK_SRC_PAIRS) || defined(RADIX_BLOCK_DST_PAIRS)
#extension GL_ARB_gpu_shader_int64 : require
#endif

#if defined(RADIX_BLOCK_SRC_PAIRS)
layout(std430, binding = RADIX_BINDING_KEYS_IN) readonly buffer PairsIn { u64vec4 pairs_in[]; };
uvec4 low4(u64vec4 q) { return uvec4(unpackUint2x32(q.x).x, unpackUint2x32(q.y).x,
                                     unpackUint2x32(q.z).x, unpackUint2x32(q.w).x); }
uvec4 high4(u64vec4 q) { return uvec4(unpackUint2x32(q.x).y, unpackUint2x32(q.y).y,
                                      unpackUint2x32(q.z).y, unpackUint2x32(q.w).y); }
#define LOAD4(i, k, v) { u64vec4 q_ = pairs_in[(i) >> 2]; k = low4(q_); v = high4(q_); }
#define LOAD1(i, k, v) { uvec2 q_ = unpackUint2x32(pairs_in[(i) >> 2][(i) & 3u]); k = q_.x; v = q_.y; }
#define KEYS4(i) low4(pairs_in[(i) >> 2])
#define KEY1(i) unpackUint2x32(pairs_in[(i) >> 2][(i) & 3u]).x
#else
layout(std430, binding = RADIX_BINDING_KEYS_IN) readonly buffer KeysIn { uvec4 keys_in[]; };
layout(std430, binding = RADIX_BINDING_VALS_IN) readonly buffer ValsIn { uvec4 vals_in[]; };
#define LOAD4(i, k, v) { k = keys_in[(i) >> 2]; v = vals_in[(i) >> 2]; }
#define LOAD1(i, k, v) { k = keys_in[(i) >> 2][(i) & 3u]; v = vals_in[(i) >> 2][(i) & 3u]; }
#define KEYS4(i) keys_in[(i) >> 2]
#define KEY1(i) keys_in[(i) >> 2][(i) & 3u]
#endif

#if defined(RADIX_BLOCK_DST_PAIRS)
layout(std430, binding = RADIX_BINDING_KEYS_OUT) writeonly buffer PairsOut { uint64_t pairs_out[]; };
#define STORE1(o, k, v) pairs_out[o] = packUint2x32(uvec2(k, v))
#else
layout(std430, binding = RADIX_BINDING_KEYS_OUT) buffer KeysOut { uint keys_out[]; };
layout(std430, binding = RADIX_BINDING_VALS_OUT) buffer ValsOut { uint vals_out[]; };
#define STORE1(o, k, v) { keys_out[o] = k; vals_out[o] = v; }
#endif
