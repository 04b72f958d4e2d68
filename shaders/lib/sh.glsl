// Real spherical harmonics colour, DESIGN.md section 1:
//   c = max(sum_lm h_lm Y_lm(d) + 0.5, 0), trig-free polynomial basis, degree <= SH_DEGREE.
// Twin: splatgl/splatmath/project.py sh_basis(), sh_color().
// Needs SH_DEGREE, SH_REST_COEFFS and, for degree > 0, the sh_rest buffer (lib/scene.glsl).
// dc is the degree-0 coefficient.

#if SH_DEGREE > 0
#ifdef SH_HALF
float sh_rest_value(uint h) {
    vec2 pair = unpackHalf2x16(sh_rest_h[h >> 1u]);
    return (h & 1u) == 0u ? pair.x : pair.y;
}
#else
float sh_rest_value(uint h) { return sh_rest[h]; }
#endif
// Coefficient k >= 1 of a splat (RGB), from the buffer holding coefficients 1..K-1.
vec3 sh_coeff(uint splat, int k) {
    uint base = (splat * uint(SH_REST_COEFFS) + uint(k - 1)) * 3u;
    return vec3(sh_rest_value(base), sh_rest_value(base + 1u), sh_rest_value(base + 2u));
}
#endif

vec3 sh_color(uint splat, vec3 dc, vec3 d) {
    vec3 c = SH_C0 * dc;
#if SH_DEGREE > 0
    float x = d.x, y = d.y, z = d.z;
    c += -SH_C1 * y * sh_coeff(splat, 1) + SH_C1 * z * sh_coeff(splat, 2) - SH_C1 * x * sh_coeff(splat, 3);
#if SH_DEGREE > 1
    float xx = x * x, yy = y * y, zz = z * z, xy = x * y, yz = y * z, xz = x * z;
    c += SH_C2_0 * xy * sh_coeff(splat, 4) + SH_C2_1 * yz * sh_coeff(splat, 5)
       + SH_C2_2 * (2.0 * zz - xx - yy) * sh_coeff(splat, 6) + SH_C2_3 * xz * sh_coeff(splat, 7)
       + SH_C2_4 * (xx - yy) * sh_coeff(splat, 8);
#if SH_DEGREE > 2
    c += SH_C3_0 * y * (3.0 * xx - yy) * sh_coeff(splat, 9)
       + SH_C3_1 * xy * z * sh_coeff(splat, 10)
       + SH_C3_2 * y * (4.0 * zz - xx - yy) * sh_coeff(splat, 11)
       + SH_C3_3 * z * (2.0 * zz - 3.0 * xx - 3.0 * yy) * sh_coeff(splat, 12)
       + SH_C3_4 * x * (4.0 * zz - xx - yy) * sh_coeff(splat, 13)
       + SH_C3_5 * z * (xx - yy) * sh_coeff(splat, 14)
       + SH_C3_6 * x * (xx - 3.0 * yy) * sh_coeff(splat, 15);
#endif
#endif
#endif
    return max(c + SH_OFFSET, vec3(0.0));
}
