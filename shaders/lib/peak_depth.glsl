// The depth at which a splat's Gaussian peaks along a pixel's ray: the key of the per-pixel
// order (PER_PIXEL; derivation in splatgl/reference/per_pixel.py).
// Twin: splatgl/splatmath/peak.py peak_coefficients(), peak_depth().
//   perspective: t* = mu_z (A + B.delta) / (A + 2 B.delta + delta^T Q2 delta), delta = a - m,
//     m = mu.xy / mu_z, A = m'^T Q m', B = (Q m')_xy with m' = (m, 1), Q2 the xy block of Q;
//   orthographic: t* = mu_z + B.delta, delta = a - mu.xy, B = -(Q_zx, Q_zy) / Q_zz;
//   a = ((x - cx) / fx, (y - cy) / fy) at pixel centre (x, y); Q = W R S^-2 R^T W^T scaled by
//   the smallest squared scale.
//   t* is clamped to mu_z +- r_z, r_z = PEAK_CLAMP_SIGMAS sqrt(Sigma_zz) (the splat's depth range).
// Coefficients as three vec4: (m or mu.xy, mu_z, A), (B, Q2_xx, Q2_xy), (Q2_yy, r_z, 0, 0).

void peak_coefficients(mat3 view_rot, mat3 rot, vec3 scale, vec3 mu, out vec4 c0, out vec4 c1,
                       out vec4 c2) {
    vec3 inv = vec3(min(scale.x, min(scale.y, scale.z))) / scale;
    mat3 m = view_rot * rot;
    mat3 q = m * mat3(inv.x * inv.x, 0.0, 0.0, 0.0, inv.y * inv.y, 0.0, 0.0, 0.0, inv.z * inv.z)
             * transpose(m);
    vec3 mz = vec3(m[0][2], m[1][2], m[2][2]) * scale;       // row z of m S
    float r_z = PEAK_CLAMP_SIGMAS * sqrt(dot(mz, mz));
#ifdef ORTHOGRAPHIC
    c0 = vec4(mu, 0.0);
    c1 = vec4(-q[0][2] / q[2][2], -q[1][2] / q[2][2], 0.0, 0.0);
    c2 = vec4(0.0, r_z, 0.0, 0.0);
#else
    vec3 c = vec3(mu.xy / mu.z, 1.0);
    vec3 qc = q * c;
    c0 = vec4(c.xy, mu.z, dot(c, qc));
    c1 = vec4(qc.xy, q[0][0], q[1][0]);
    c2 = vec4(q[1][1], r_z, 0.0, 0.0);
#endif
}

// t* at ray coordinates a of a splat with coefficients (c0, c1, c2), clamped to mu_z +- r_z; the
// centre's depth where the denominator is not positive (rounding, a degenerate splat).
float peak_depth(vec4 c0, vec4 c1, vec2 c2, vec2 a) {
    vec2 d = a - c0.xy;
    float lin = c1.x * d.x + c1.y * d.y;
#ifdef ORTHOGRAPHIC
    float t = c0.z + lin;
#else
    float den = c0.w + lin + lin + (c1.z * d.x * d.x + c2.x * d.y * d.y) + (c1.w + c1.w) * d.x * d.y;
    float t = den > 0.0 ? c0.z * (c0.w + lin) / den : c0.z;
#endif
    return min(max(t, c0.z - c2.y), c0.z + c2.y);
}
