// Projections by angle: fisheye (OpenCV's model, equidistant when k = 0) and equirectangular.
// Twin: splatgl/cameras/lens.py (same names; formulas and their derivation in its module doc).
// Included by lib/project.glsl; compiled only when FISHEYE or EQUIRECT defines LENS.
#ifdef LENS

#ifdef FISHEYE
// theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8), k = u_distortion.
float fisheye_theta_d(float theta) {
    float t2 = theta * theta;
    vec4 k = u_distortion;
    return theta * (1.0 + t2 * (k.x + t2 * (k.y + t2 * (k.z + t2 * k.w))));
}

// d theta_d / d theta.
float fisheye_theta_d_prime(float theta) {
    float t2 = theta * theta;
    vec4 k = u_distortion;
    return 1.0 + t2 * (3.0 * k.x + t2 * (5.0 * k.y + t2 * (7.0 * k.z + t2 * 9.0 * k.w)));
}

// (s, c2, g', R^2) of the fisheye map: u = fx s x + cx, and the Jacobian's
// c2 = (g' z / R^2 - s) / rho^2; series near the axis, where both cancel.
vec4 fisheye_terms(vec3 p) {
    float rho2 = p.x * p.x + p.y * p.y;
    float rho = sqrt(rho2);
    float r2 = rho2 + p.z * p.z;
    float theta = atan(rho, p.z);
    float gp = fisheye_theta_d_prime(theta);
    if (rho < FISHEYE_SERIES_RHO * p.z) {
        float t = rho2 / (p.z * p.z);
        float s = (1.0 + (u_distortion.x - 1.0 / 3.0) * t) / p.z;
        float c2 = (2.0 * u_distortion.x - 2.0 / 3.0) / (p.z * p.z * p.z);
        return vec4(s, c2, gp, r2);
    }
    float s = fisheye_theta_d(theta) / rho;
    return vec4(s, (gp * p.z / r2 - s) / rho2, gp, r2);
}
#endif

#ifdef EQUIRECT
// Omni-directional stereo (splatgl/cameras/lens.py eye_space): p relative to the eye on the circle of
// radius |u_ods_eye| whose tangent ray reaches it; phi = atan2(x, z) - asin(eye / D).
vec3 eye_space(vec3 p) {
    if (u_ods_eye == 0.0) return p;
    float d = max(length(p.xz), abs(u_ods_eye));
    float phi = (p.x == 0.0 && p.z == 0.0 ? 0.0 : atan(p.x, p.z)) - asin(u_ods_eye / d);
    return p - u_ods_eye * vec3(cos(phi), 0.0, -sin(phi));
}
#endif

vec2 project_lens(vec3 p) {
#ifdef FISHEYE
    float s = fisheye_terms(p).x;
    return u_intrinsics.xy * s * p.xy + u_intrinsics.zw;
#else
    float r = sqrt(p.x * p.x + p.z * p.z);
    // GLSL leaves atan(0, 0) undefined; at an exact pole the longitude is 0, as atan2 gives
    // (stress case equirect_poles: llvmpipe's value moved the pole band's half-turn clip).
    float lon = (p.x == 0.0 && p.z == 0.0) ? 0.0 : atan(p.x, p.z);
    return u_intrinsics.xy * vec2(lon, atan(p.y, r)) + u_intrinsics.zw;
#endif
}

// Jacobian of project_lens, in jacobian()'s layout (rows of J in the first two rows).
mat3 jacobian_lens(vec3 p) {
    float fx = u_intrinsics.x, fy = u_intrinsics.y;
#ifdef FISHEYE
    vec4 t = fisheye_terms(p);  // (s, c2, g', R^2)
    return transpose(mat3(fx * (t.x + p.x * p.x * t.y), fx * p.x * p.y * t.y, -fx * p.x * t.z / t.w,
                          fy * p.x * p.y * t.y, fy * (t.x + p.y * p.y * t.y), -fy * p.y * t.z / t.w,
                          0.0, 0.0, 0.0));
#else
    float big_r2 = dot(p, p);
    float r = max(sqrt(p.x * p.x + p.z * p.z), EQUIRECT_POLE_EPS * sqrt(big_r2));
    return transpose(mat3(fx * p.z / (r * r), 0.0, -fx * p.x / (r * r),
                          -fy * p.x * p.y / (big_r2 * r), fy * r / big_r2, -fy * p.z * p.y / (big_r2 * r),
                          0.0, 0.0, 0.0));
#endif
}
#endif  // LENS
