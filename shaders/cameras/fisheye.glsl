// Fisheye camera model: OpenCV's model, equidistant when k = 0 (FISHEYE is defined too).
// Formulas and their derivation in splatgl/cameras/fisheye.py's module doc.  fx, fy in pixels
// per radian.
// Twin: splatgl/cameras/fisheye.py Fisheye.project(), Fisheye.jacobian(), Fisheye.visible(),
//   Fisheye.depth().
uniform vec4 u_distortion;    // k1..k4
uniform float u_theta_limit;  // largest angle from the axis kept (radians)

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

// Pixel position of a camera-space point: u = fx s x + cx.
vec2 project_mean(vec3 p) {
    float s = fisheye_terms(p).x;
    return u_intrinsics.xy * s * p.xy + u_intrinsics.zw;
}

// Jacobian of project_mean, in the pinhole's layout (rows of J in the first two rows).
mat3 jacobian(vec3 p) {
    float fx = u_intrinsics.x, fy = u_intrinsics.y;
    vec4 t = fisheye_terms(p);  // (s, c2, g', R^2)
    return transpose(mat3(fx * (t.x + p.x * p.x * t.y), fx * p.x * p.y * t.y, -fx * p.x * t.z / t.w,
                          fy * p.x * p.y * t.y, fy * (t.x + p.y * p.y * t.y), -fy * p.y * t.z / t.w,
                          0.0, 0.0, 0.0));
}

// Whether a camera-space centre is drawn: distance beyond the near plane, and the angle from
// the axis within u_theta_limit (a fisheye sees behind the camera plane).
bool in_view(vec3 p) {
    if (!(length(p) > u_near)) return false;
    if (!(atan(length(p.xy), p.z) <= u_theta_limit)) return false;
    return true;
}

// Depth for the sort and the depth layer: the distance from the camera.
float view_depth(vec3 p) {
    return length(p);
}
