// 2DGS surfels (Huang et al. 2024, "2D Gaussian Splatting"), DESIGN.md section 1.
// Twin: splatgl/splatmath/surfel.py surfel_screen(), sigma_count(), surfel_bounds(), surfel_alpha().
// Each function has the name of its twin.  Needs lib/camera.glsl.
//
// T = P H maps tangent-plane (u, v, 1) to homogeneous pixels (paper eq. 5: H's columns are
// (s_u t_u, 0), (s_v t_v, 0), (p, 1); P = K [R | t], orthographic P = [[fx R_0, fx t_0 + cx],
// [fy R_1, fy t_1 + cy], [0, 0, 0, 1]]).  Everything here uses the centred T' = A T, A the
// translation of pixel coordinates by -c (c = projected centre): T'_02 = T'_12 = 0 exactly and
// pixel offsets d = x - c stay small, so float32 keeps its precision away from the principal point.

// Centred transform from the camera-space columns of W H: a_u = R s_u t_u, a_v = R s_v t_v, p.
void surfel_screen(vec3 p, vec3 a_u, vec3 a_v, out vec2 center, out vec3 t0, out vec3 t1,
                   out vec3 t2) {
#ifdef ORTHOGRAPHIC
    center = u_intrinsics.xy * p.xy + u_intrinsics.zw;
    t0 = vec3(u_intrinsics.x * vec2(a_u.x, a_v.x), 0.0);
    t1 = vec3(u_intrinsics.y * vec2(a_u.y, a_v.y), 0.0);
    t2 = vec3(0.0, 0.0, 1.0);
#else
    vec2 m = p.xy / p.z;
    center = u_intrinsics.xy * m + u_intrinsics.zw;
    // Row r of K [R|t] H minus c_r times row 2: f_r (a.r - m_r a.z); the cx, cy terms cancel.
    t0 = vec3(u_intrinsics.x * (vec2(a_u.x, a_v.x) - m.x * vec2(a_u.z, a_v.z)), 0.0);
    t1 = vec3(u_intrinsics.y * (vec2(a_u.y, a_v.y) - m.y * vec2(a_u.z, a_v.z)), 0.0);
    t2 = vec3(a_u.z, a_v.z, p.z);
#endif
}

// k = sqrt(2 ln(o / ALPHA_MIN)): beyond u^2 + v^2 = k^2 the surfel's alpha is below 1/255.
float sigma_count(float opacity) {
    return sqrt(max(2.0 * log(opacity / ALPHA_MIN), 0.0));
}

// Screen box [lo, hi] (pixels, clamped to the viewport) of the ellipse u^2 + v^2 <= k^2 united
// with the low-pass disc |x - c| <= k / sqrt(F).  The ellipse's image has the dual conic
// C* = T' diag(k^2, k^2, -1) T'^T; the tangent lines x = c + X solve
// C*_00 - 2 X C*_02 + X^2 C*_22 = 0: X = x_c +- sqrt(x_c^2 - C*_00 / C*_22), x_c = C*_02 / C*_22.
// C*_22 < 0 while the ellipse is in front of the camera; if it reaches the near plane the image
// is unbounded and the box is the whole viewport.  False: cull (empty, NaN or o <= 1/255).
bool surfel_bounds(vec2 center, vec3 t0, vec3 t1, vec3 t2, float opacity, out vec2 lo,
                   out vec2 hi) {
    float k = sigma_count(opacity);
    float k2 = k * k;
    float a2 = dot(t2.xy, t2.xy);
    float c22 = k2 * a2 - t2.z * t2.z;
    vec2 c_rr = k2 * vec2(dot(t0.xy, t0.xy), dot(t1.xy, t1.xy));
    vec2 c_r2 = k2 * vec2(dot(t0.xy, t2.xy), dot(t1.xy, t2.xy));
    vec2 xc = c_r2 / c22;
    vec2 ext = sqrt(max(xc * xc - c_rr / c22, 0.0));
    float r_lp = k / sqrt(SURFEL_FILTER_INV_SQUARE);
    lo = center + min(xc - ext, vec2(-r_lp));
    hi = center + max(xc + ext, vec2(r_lp));
#ifndef ORTHOGRAPHIC
    if (!(t2.z - k * sqrt(a2) > u_near)) {  // nearest point of the k-ellipse, view z
        lo = vec2(0.0);
        hi = u_viewport;
    }
#endif
    if (any(isnan(vec4(lo, hi))) || any(isnan(center)) || any(isinf(center))) return false;
    lo = clamp(lo, vec2(0.0), u_viewport);
    hi = clamp(hi, vec2(0.0), u_viewport);
    return k > 0.0 && hi.x > lo.x && hi.y > lo.y;
}

// Ray-splat intersection and opacity at pixel offset d = x - c (pixels), eq. 8-11:
//   h_u = T_0 - x T_2, h_v = T_1 - y T_2 (eq. 9; centred rows and d here),
//   (u, v, 1) ~ h_u x h_v (eq. 10), rho_3d = u^2 + v^2, rho_2d = F |d|^2 (low pass, eq. 11),
//   alpha = min(0.99, o exp(-min(rho_3d, rho_2d) / 2)).
// No hit (ray parallel to the plane, or meeting it behind the camera): the low pass alone.
// depth: camera z of the hit, depth_row . (u, v, 1), where rho_3d <= rho_2d; else the centre's.
float surfel_alpha(vec3 t0, vec3 t1, vec3 t2, vec3 depth_row, float opacity, vec2 d,
                   out float depth) {
    vec3 hu = t0 - d.x * t2;
    vec3 hv = t1 - d.y * t2;
    vec3 p = cross(hu, hv);
    vec2 s = p.z != 0.0 ? p.xy / p.z : vec2(0.0);
    float w = dot(t2, vec3(s, 1.0));
    bool hit = p.z != 0.0 && w > 0.0 && !any(isnan(s)) && !any(isinf(s));
    float rho3d = hit ? dot(s, s) : 3.0e38;
    float rho2d = SURFEL_FILTER_INV_SQUARE * dot(d, d);
    depth = rho3d <= rho2d ? dot(depth_row, vec3(s, 1.0)) : depth_row.z;
    return min(ALPHA_MAX, opacity * exp(-0.5 * min(rho3d, rho2d)));
}
