// OpenCV camera model: a pinhole with OpenCV's radial-tangential lens distortion; formulas and
// their derivation in splatgl/cameras/opencv.py's module doc.
// Twin: splatgl/cameras/opencv.py radial(), OpenCV.project(), OpenCV.jacobian(),
//   OpenCV.visible().
uniform vec3 u_cv_num;         // k1, k2, k3: R's numerator 1 + k1 r^2 + k2 r^4 + k3 r^6
uniform vec3 u_cv_den;         // k4, k5, k6: R's denominator 1 + k4 r^2 + k5 r^4 + k6 r^6
uniform vec2 u_cv_tangential;  // p1, p2
uniform float u_cv_r2_limit;   // squared normalised radius of the fold: centres beyond are not drawn
uniform vec4 u_cv_jac_box;     // (a_lo, a_hi, b_lo, b_hi): x/z, y/z clamped to it in the Jacobian

// (R, dR / d r^2) of the rational radial factor at r2 = r^2.
vec2 opencv_radial(float r2) {
    vec3 k = u_cv_num, q = u_cv_den;
    float num = 1.0 + r2 * (k.x + r2 * (k.y + r2 * k.z));
    float den = 1.0 + r2 * (q.x + r2 * (q.y + r2 * q.z));
    float dnum = k.x + r2 * (2.0 * k.y + 3.0 * r2 * k.z);
    float dden = q.x + r2 * (2.0 * q.y + 3.0 * r2 * q.z);
    return vec2(num / den, (dnum * den - num * dden) / (den * den));
}

// Distorted normalised coordinates of n = (x/z, y/z):
// a_d = a R + 2 p1 a b + p2 (r^2 + 2 a^2), b_d = b R + p1 (r^2 + 2 b^2) + 2 p2 a b.
vec2 opencv_distort(vec2 n) {
    float r2 = dot(n, n);
    float p1 = u_cv_tangential.x, p2 = u_cv_tangential.y;
    return n * opencv_radial(r2).x + vec2(2.0 * p1 * n.x * n.y + p2 * (r2 + 2.0 * n.x * n.x),
                                          p1 * (r2 + 2.0 * n.y * n.y) + 2.0 * p2 * n.x * n.y);
}

// Pixel position of a camera-space point: u = fx a_d + cx, v = fy b_d + cy.
vec2 project_mean(vec3 p) {
    return u_intrinsics.xy * opencv_distort(p.xy / p.z) + u_intrinsics.zw;
}

// J = diag(fx, fy) D P: D the distortion's symmetric 2x2 Jacobian, P the pinhole's
// [[1/z, 0, -a/z], [0, 1/z, -b/z]], both at n = (a, b) = (x/z, y/z) clamped to u_cv_jac_box.
// In the pinhole's layout (rows of J in the first two rows).
mat3 jacobian(vec3 p) {
    vec2 n = clamp(p.xy / p.z, u_cv_jac_box.xz, u_cv_jac_box.yw);
    vec2 rg = opencv_radial(dot(n, n));  // (R, g)
    float p1 = u_cv_tangential.x, p2 = u_cv_tangential.y;
    float off = 2.0 * n.x * n.y * rg.y + 2.0 * p1 * n.x + 2.0 * p2 * n.y;
    float d00 = rg.x + 2.0 * n.x * n.x * rg.y + 2.0 * p1 * n.y + 6.0 * p2 * n.x;
    float d11 = rg.x + 2.0 * n.y * n.y * rg.y + 6.0 * p1 * n.y + 2.0 * p2 * n.x;
    vec3 p0 = vec3(1.0, 0.0, -n.x) / p.z;
    vec3 q1 = vec3(0.0, 1.0, -n.y) / p.z;
    vec3 j0 = u_intrinsics.x * (d00 * p0 + off * q1);
    vec3 j1 = u_intrinsics.y * (off * p0 + d11 * q1);
    return transpose(mat3(j0, j1, vec3(0.0)));
}

// Whether a camera-space centre is drawn: view z beyond the near plane (before any divide)
// and x/z, y/z inside the fold radius.
bool in_view(vec3 p) {
    if (!(p.z > u_near)) return false;
    vec2 n = p.xy / p.z;
    return dot(n, n) < u_cv_r2_limit;
}

// Depth of a camera-space centre for the sort and the depth layer: view z.
float view_depth(vec3 p) {
    return p.z;
}
