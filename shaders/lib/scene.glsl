// Scene storage, uploaded once per scene (splatgl/gl/scene_buffers.py writes these layouts).
// Twin: none (storage layouts and accessors; the compact decoding's twin is in dequantise.glsl).
// Shaders read a splat only through the accessors below, so every storage layout
// (splatgl.settings.GpuStorage) serves every stage.
//
// float32 layout: splat_a[i] = (mean.xyz - anchor, opacity), splat_q[i] = unit quaternion
// (w, x, y, z), splat_s[i] = (scale.xyz world units, 0), splat_dc[i] = (SH degree-0 RGB, 0).
// COMPACT_STORAGE: splat_packed[2i], splat_packed[2i + 1] (splatgl/gl/storage.py, lib/dequantise.glsl).
// sh_rest holds SH_REST_COEFFS * 3 values per splat (coefficients 1.., coefficient-major with
// RGB last, as in Scene.sh), float32 or (SH_HALF) float16, at the degree the program is
// specialised for.
#ifdef COMPACT_STORAGE
#include "lib/dequantise.glsl"
layout(std430, binding = BINDING_A) readonly buffer SplatPacked { uvec4 splat_packed[]; };

vec4 splat_mean_opacity(uint i) {
    uvec4 w = splat_packed[2u * i];
    return vec4(uintBitsToFloat(w.xyz), decode_opacity(w.w));
}
vec4 splat_rotation(uint i) {
    return decode_rotation(splat_packed[2u * i + 1u].x, splat_packed[2u * i].w);
}
vec3 splat_scale(uint i) {
    vec3 scale, dc;
    decode_scale_dc(splat_packed[2u * i + 1u].yzw, scale, dc);
    return scale;
}
vec3 splat_sh_dc(uint i) {
    vec3 scale, dc;
    decode_scale_dc(splat_packed[2u * i + 1u].yzw, scale, dc);
    return dc;
}
#else
layout(std430, binding = BINDING_A) readonly buffer SplatA { vec4 splat_a[]; };
layout(std430, binding = BINDING_Q) readonly buffer SplatQ { vec4 splat_q[]; };
layout(std430, binding = BINDING_S) readonly buffer SplatS { vec4 splat_s[]; };
layout(std430, binding = BINDING_DC) readonly buffer SplatDC { vec4 splat_dc[]; };

vec4 splat_mean_opacity(uint i) { return splat_a[i]; }
vec4 splat_rotation(uint i) { return splat_q[i]; }
vec3 splat_scale(uint i) { return splat_s[i].xyz; }
vec3 splat_sh_dc(uint i) { return splat_dc[i].rgb; }
#endif

#if SH_DEGREE > 0 && defined(SH_HALF)
// Half-float storage: two coefficients per uint (unpackHalf2x16: low half first).
layout(std430, binding = BINDING_SH) readonly buffer SplatSH { uint sh_rest_h[]; };
#elif SH_DEGREE > 0
layout(std430, binding = BINDING_SH) readonly buffer SplatSH { float sh_rest[]; };
#endif
