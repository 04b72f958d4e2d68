// Decoding of the compact scene storage (splatgl/gl/storage.py: layout, encoder and the NumPy twin
// decode_compact; --gpu-storage compact).  Needs COMPACT_QUAT_BITS, COMPACT_OPACITY_BITS and the
// per-scene COMPACT_SCALE_UNIT (2^e, storage.scale_exponent) as defines.
// Twin: splatgl/gl/storage.py decode_compact().

// Unit quaternion (w, x, y, z) from its smallest-three words: three COMPACT_QUAT_BITS unorms
// mapping [-1/sqrt 2, 1/sqrt 2] (two in `word` bits 0.., the third in `word3` above the
// opacity), the index of the largest (>= 0) component in `word` bits 30-31; the largest is
// sqrt(1 - |others|^2).
vec4 decode_rotation(uint word, uint word3) {
    uint mask = (1u << uint(COMPACT_QUAT_BITS)) - 1u;
    uvec3 k = uvec3(word, word >> uint(COMPACT_QUAT_BITS), word3 >> uint(COMPACT_OPACITY_BITS)) & mask;
    vec3 c = (vec3(k) / float(mask) * 2.0 - 1.0) * 0.70710678118654752;
    float l = sqrt(max(0.0, 1.0 - dot(c, c)));
    uint largest = word >> 30u;
    if (largest == 0u) return vec4(l, c);
    if (largest == 1u) return vec4(c.x, l, c.yz);
    if (largest == 2u) return vec4(c.xy, l, c.z);
    return vec4(c, l);
}

// Linear opacity from its COMPACT_OPACITY_BITS unorm (low bits of word 3).
float decode_opacity(uint word) {
    uint mask = (1u << uint(COMPACT_OPACITY_BITS)) - 1u;
    return float(word & mask) / float(mask);
}

// (scale.xyz world units, dc.rgb) from the three float16-pair words 5-7.
void decode_scale_dc(uvec3 words, out vec3 scale, out vec3 dc) {
    vec2 a = unpackHalf2x16(words.x), b = unpackHalf2x16(words.y), c = unpackHalf2x16(words.z);
    scale = vec3(a, b.x) * COMPACT_SCALE_UNIT;
    dc = vec3(b.y, c);
}
