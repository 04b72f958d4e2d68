// Equirectangular camera model: a longitude/latitude panorama (EQUIRECT is defined too, for
// the seam copies of lib/splat_setup.glsl and quad.frag).  Formulas in
// splatgl/cameras/equirect.py's module doc.
// Twin: splatgl/cameras/equirect.py eye_space(), Equirectangular.project(),
//   Equirectangular.jacobian(), Equirectangular.visible(), Equirectangular.depth().
uniform float u_wrap_period;  // pixels per turn of longitude (2 pi fx)
uniform float u_ods_eye;      // omni-directional stereo: signed eye offset on the eye circle (0: mono)

// Omni-directional stereo (splatgl/cameras/equirect.py eye_space): p relative to the eye on the
// circle of radius |u_ods_eye| whose tangent ray reaches it; phi = atan2(x, z) - asin(eye / D).
vec3 eye_space(vec3 p) {
    if (u_ods_eye == 0.0) return p;
    float d = max(length(p.xz), abs(u_ods_eye));
    float phi = (p.x == 0.0 && p.z == 0.0 ? 0.0 : atan(p.x, p.z)) - asin(u_ods_eye / d);
    return p - u_ods_eye * vec3(cos(phi), 0.0, -sin(phi));
}

// Pixel position of a camera-space point: u = fx lon + cx, v = fy lat + cy.
vec2 project_mean(vec3 p) {
    float r = sqrt(p.x * p.x + p.z * p.z);
    // GLSL leaves atan(0, 0) undefined; at an exact pole the longitude is 0, as atan2 gives
    // (stress case equirect_poles: llvmpipe's value moved the pole band's half-turn clip).
    float lon = (p.x == 0.0 && p.z == 0.0) ? 0.0 : atan(p.x, p.z);
    return u_intrinsics.xy * vec2(lon, atan(p.y, r)) + u_intrinsics.zw;
}

// Jacobian of project_mean, in the pinhole's layout (rows of J in the first two rows).
mat3 jacobian(vec3 p) {
    float fx = u_intrinsics.x, fy = u_intrinsics.y;
    float big_r2 = dot(p, p);
    float r = max(sqrt(p.x * p.x + p.z * p.z), EQUIRECT_POLE_EPS * sqrt(big_r2));
    return transpose(mat3(fx * p.z / (r * r), 0.0, -fx * p.x / (r * r),
                          -fy * p.x * p.y / (big_r2 * r), fy * r / big_r2, -fy * p.z * p.y / (big_r2 * r),
                          0.0, 0.0, 0.0));
}

// Whether a camera-space centre is drawn: distance beyond the near plane (a panorama sees
// every direction).
bool in_view(vec3 p) {
    if (!(length(p) > u_near)) return false;
    return true;
}

// Depth for the sort and the depth layer: the distance from the camera.
float view_depth(vec3 p) {
    return length(p);
}
