// Per-splat projection math, DESIGN.md section 1; each function has the name of its twin.
// Twin: splatgl/scene/quaternion.py quat_to_rotmat();
//   splatgl/splatmath/project.py covariance_3d(), covariance_2d(), screen_factor(),
//   covariance_2d_det(), conic(), discriminant(), antialias_factor(), reference_radius(),
//   ellipse_axes().
// The camera model's project_mean, jacobian, in_view and view_depth come from its piece in
// cameras/, included by lib/camera.glsl.

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

// The screen-space dilation (px^2): LOW_PASS, or with VIEW_LOW_PASS the view's own
// (splatgl.cameras.view.View.low_pass: a draft drawn at a fraction s of its window's pixels
// dilates by LOW_PASS s^2, the full-size frame's 0.3 px^2 in its own larger pixels).
#ifdef VIEW_LOW_PASS
uniform float u_low_pass;
#define SPLAT_LOW_PASS u_low_pass
#else
#define SPLAT_LOW_PASS LOW_PASS
#endif

// Sigma' = J W Sigma W^T J^T + SPLAT_LOW_PASS I, returned as (xx, xy, yy) in pixels^2.
vec3 covariance_2d(mat3 cov3d, vec3 p) {
    mat3 t = jacobian(p) * u_view_rot;
    mat3 c = t * cov3d * transpose(t);
    return vec3(c[0][0] + SPLAT_LOW_PASS, c[1][0], c[1][1] + SPLAT_LOW_PASS);
}

// M = J W R S (rows 0 and 1 of the returned matrix; row 2 is zero): Sigma' = M M^T + LOW_PASS I.
mat3 screen_factor(mat3 rot, vec3 scale, vec3 p) {
    return jacobian(p) * u_view_rot * rot * mat3(scale.x, 0.0, 0.0, 0.0, scale.y, 0.0, 0.0, 0.0, scale.z);
}

// det(Sigma') = det(M M^T) + LOW_PASS tr(M M^T) + LOW_PASS^2, det(M M^T) = |r0 x r1|^2 (the
// squared 2x2 minors, Cauchy-Binet).  Guard (stress case det_nonpositive): a c - b^2 of a long
// needle at 45 degrees cancels to <= 0 in float32 and the splat vanished (max error 0.35); this
// form is >= LOW_PASS^2 > 0, and +inf on overflow (a zero conic: a uniform veil).  It is used
// only where a c - b^2 has cancelled (below DET_CANCEL_RATIO a c: relative error over ~1e-5).
float covariance_2d_det(vec3 cov, mat3 m) {
    float det = cov.x * cov.z - cov.y * cov.y;  // the reference's form, kept where it is accurate
    if (det > DET_CANCEL_RATIO * (cov.x * cov.z)) return det;
    vec3 r0 = vec3(m[0][0], m[1][0], m[2][0]);
    vec3 r1 = vec3(m[0][1], m[1][1], m[2][1]);
    vec3 minors = cross(r0, r1);
    return dot(minors, minors) + SPLAT_LOW_PASS * (dot(r0, r0) + dot(r1, r1))
           + SPLAT_LOW_PASS * SPLAT_LOW_PASS;
}

// Q = Sigma'^-1 as (a, b, c) from the adjugate and det (covariance_2d_det); det <= 0 is the
// caller's to cull.
vec3 conic(vec3 cov, float det) {
    float inv = 1.0 / det;
    return vec3(cov.z * inv, -cov.y * inv, cov.x * inv);
}

// mid^2 - det, the reference's form.  Guard (stress case near_tiny): beyond ~1e19 px^2 both terms
// overflow and inf - inf is NaN (the extent became garbage, max error 0.26); there the equal
// ((a - c) / 2)^2 + b^2 is used, which may be +inf but never NaN.
float discriminant(vec3 cov) {
    float mid = 0.5 * (cov.x + cov.z);
    float disc = mid * mid - (cov.x * cov.z - cov.y * cov.y);
    float half_diff = 0.5 * (cov.x - cov.z);
    return (isnan(disc) || isinf(disc)) ? half_diff * half_diff + cov.y * cov.y : disc;
}

// sqrt(max(2.5e-5, det(Sigma') / det(Sigma' + 0.3 I))) for the dilated covariance cov.
float antialias_factor(vec3 cov) {
    float det_dilated = cov.x * cov.z - cov.y * cov.y;
    float det = (cov.x - SPLAT_LOW_PASS) * (cov.z - SPLAT_LOW_PASS) - cov.y * cov.y;
    return sqrt(max(AA_MIN_FACTOR, det / det_dilated));
}

// Reference extent: ceil(3 sqrt(lambda_max)), lambda = mid +- sqrt(max(0.1, mid^2 - det)).
float reference_radius(vec3 cov) {
    float mid = 0.5 * (cov.x + cov.z);
    float lambda_max = mid + sqrt(max(EXTENT_DISCRIMINANT_FLOOR, discriminant(cov)));
    return ceil(EXTENT_SIGMAS * sqrt(lambda_max));
}

// Opacity-aware half-axes of the quad (columns), in pixels: along each eigenvector,
// sqrt(2 ln(255 o)) sqrt(lambda), where o exp(-r^2/2) falls to ALPHA_MIN.
// Guard (stress case det_nonpositive): lam2 = mid - root cancelled to 0 for a long thin splat
// (entries ~3e7, lam2 0.3) and the quad had no width (max error 0.35); lam2 = det / lam1 with the
// accurate det (covariance_2d_det) does not cancel.
mat2 ellipse_axes(vec3 cov, float det, float opacity) {
    float a = cov.x, b = cov.y, c = cov.z;
    float mid = 0.5 * (a + c);
    float root = sqrt(max(discriminant(cov), 0.0));
    // (det overflowing to +inf gives det / lam1 = inf: lam2 <= lam1 bounds it.)
    float lam1 = mid + root, lam2 = lam1 > 0.0 ? clamp(det / lam1, 0.0, lam1) : 0.0;
    vec2 v1 = abs(a - lam1) < abs(c - lam1) ? vec2(lam1 - c, b) : vec2(b, lam1 - a);
    float n = length(v1);
    v1 = n > 0.0 ? v1 / n : vec2(1.0, 0.0);
    vec2 v2 = vec2(-v1.y, v1.x);
    float k = sqrt(max(2.0 * log(opacity / ALPHA_MIN), 0.0));
    return mat2(v1 * (k * sqrt(lam1)), v2 * (k * sqrt(lam2)));
}
