// Scene storage, uploaded once per scene (splatgl/gl/scene_buffers.py writes these layouts).
// splat_a[i] = (mean.xyz world, opacity), splat_q[i] = unit quaternion (w, x, y, z),
// splat_s[i] = (scale.xyz world units, 0), splat_dc[i] = (SH degree-0 RGB, 0).  sh_rest holds
// SH_REST_COEFFS * 3 floats per splat (coefficients 1.., coefficient-major with RGB last, as in
// Scene.sh), only at the degree the program is specialised for.
layout(std430, binding = 0) readonly buffer SplatA { vec4 splat_a[]; };
layout(std430, binding = 1) readonly buffer SplatQ { vec4 splat_q[]; };
layout(std430, binding = 2) readonly buffer SplatS { vec4 splat_s[]; };
layout(std430, binding = 3) readonly buffer SplatDC { vec4 splat_dc[]; };
#if SH_DEGREE > 0 && defined(SH_HALF)
// Half-float storage: two coefficients per uint (unpackHalf2x16: low half first).
layout(std430, binding = 4) readonly buffer SplatSH { uint sh_rest_h[]; };
#elif SH_DEGREE > 0
layout(std430, binding = 4) readonly buffer SplatSH { float sh_rest[]; };
#endif
