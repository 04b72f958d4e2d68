// Per-splat projection math, DESIGN.md section 1.  Twin: splatgl/project.py (same names).

// Unit quaternion (w, x, y, z) -> rotation matrix (column-major mat3: m[col][row]).
mat3 quat_to_rotmat(vec4 q) {
    float w = q.x, x = q.y, y = q.z, z = q.w;
    return mat3(
        1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + w * z), 2.0 * (x * z - w * y),
        2.0 * (x * y - w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z + w * x),
        2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y));
}

// Sigma = R S S^T R^T.
mat3 covariance_3d(mat3 rot, vec3 scale) {
    mat3 m = rot * mat3(scale.x, 0.0, 0.0, 0.0, scale.y, 0.0, 0.0, 0.0, scale.z);
    return m * transpose(m);
}

// Pixel position of a camera-space point: u = fx x/z + cx (orthographic: u = fx x + cx).
vec2 project_mean(vec3 p) {
#ifdef ORTHOGRAPHIC
    return u_intrinsics.xy * p.xy + u_intrinsics.zw;
#else
    return u_intrinsics.xy * p.xy / p.z + u_intrinsics.zw;
#endif
}

// EWA Jacobian (2x3, stored as the first two columns of a transposed mat3):
// [[fx/z, 0, -fx x/z^2], [0, fy/z, -fy y/z^2]], x/z and y/z clamped to +-1.3 tan(half fov).
// Returned as mat3 J3 with rows (J row 0, J row 1, 0) so that J3 * v = (J v, 0).
mat3 jacobian(vec3 p) {
#ifdef ORTHOGRAPHIC
    return transpose(mat3(u_intrinsics.x, 0.0, 0.0, 0.0, u_intrinsics.y, 0.0, 0.0, 0.0, 0.0));
#else
    vec2 lim = JACOBIAN_CLAMP * u_tan_fov;
    vec2 t = clamp(p.xy / p.z, -lim, lim);
    float fx = u_intrinsics.x, fy = u_intrinsics.y;
    return transpose(mat3(fx / p.z, 0.0, -fx * t.x / p.z,
                          0.0, fy / p.z, -fy * t.y / p.z,
                          0.0, 0.0, 0.0));
#endif
}

// Sigma' = J W Sigma W^T J^T + LOW_PASS I, returned as (xx, xy, yy) in pixels^2.
vec3 covariance_2d(mat3 cov3d, vec3 p) {
    mat3 t = jacobian(p) * u_view_rot;
    mat3 c = t * cov3d * transpose(t);
    return vec3(c[0][0] + LOW_PASS, c[1][0], c[1][1] + LOW_PASS);
}

// Q = Sigma'^-1 as (a, b, c); det <= 0 is the caller's to cull.
vec3 conic(vec3 cov, out float det) {
    det = cov.x * cov.z - cov.y * cov.y;
    float inv = 1.0 / det;
    return vec3(cov.z * inv, -cov.y * inv, cov.x * inv);
}

// sqrt(max(2.5e-5, det(Sigma') / det(Sigma' + 0.3 I))) for the dilated covariance cov.
float antialias_factor(vec3 cov) {
    float det_dilated = cov.x * cov.z - cov.y * cov.y;
    float det = (cov.x - LOW_PASS) * (cov.z - LOW_PASS) - cov.y * cov.y;
    return sqrt(max(AA_MIN_FACTOR, det / det_dilated));
}

// Reference extent: ceil(3 sqrt(lambda_max)), lambda = mid +- sqrt(max(0.1, mid^2 - det)).
float reference_radius(vec3 cov) {
    float mid = 0.5 * (cov.x + cov.z);
    float det = cov.x * cov.z - cov.y * cov.y;
    float lambda_max = mid + sqrt(max(EXTENT_DISCRIMINANT_FLOOR, mid * mid - det));
    return ceil(EXTENT_SIGMAS * sqrt(lambda_max));
}

// Opacity-aware half-axes of the quad (columns), in pixels: along each eigenvector,
// sqrt(2 ln(255 o)) sqrt(lambda), where o exp(-r^2/2) falls to ALPHA_MIN.
mat2 ellipse_axes(vec3 cov, float opacity) {
    float a = cov.x, b = cov.y, c = cov.z;
    float mid = 0.5 * (a + c);
    float root = sqrt(max(mid * mid - (a * c - b * b), 0.0));
    float lam1 = mid + root, lam2 = max(mid - root, 0.0);
    vec2 v1 = abs(a - lam1) < abs(c - lam1) ? vec2(lam1 - c, b) : vec2(b, lam1 - a);
    float n = length(v1);
    v1 = n > 0.0 ? v1 / n : vec2(1.0, 0.0);
    vec2 v2 = vec2(-v1.y, v1.x);
    float k = sqrt(max(2.0 * log(opacity / ALPHA_MIN), 0.0));
    return mat2(v1 * (k * sqrt(lam1)), v2 * (k * sqrt(lam2)));
}
