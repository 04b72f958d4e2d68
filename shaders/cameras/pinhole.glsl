// Pinhole camera model.  Included by lib/camera.glsl when CAMERA_MODEL is pinhole; every
// model's piece defines project_mean, jacobian, in_view and view_depth (the model's project,
// jacobian, visible and depth).
// Twin: splatgl/cameras/pinhole.py Pinhole.project(), Pinhole.jacobian(), Pinhole.visible(),
//   Pinhole.depth().

// Pixel position of a camera-space point: u = fx x/z + cx.
vec2 project_mean(vec3 p) {
    return u_intrinsics.xy * p.xy / p.z + u_intrinsics.zw;
}

// EWA Jacobian (2x3, stored as the first two columns of a transposed mat3):
// [[fx/z, 0, -fx x/z^2], [0, fy/z, -fy y/z^2]], x/z and y/z clamped to +-1.3 tan(half fov).
// Returned as mat3 J3 with rows (J row 0, J row 1, 0) so that J3 * v = (J v, 0).
mat3 jacobian(vec3 p) {
    vec2 lim = JACOBIAN_CLAMP * u_tan_fov;
    vec2 t = clamp(p.xy / p.z, -lim, lim);
    float fx = u_intrinsics.x, fy = u_intrinsics.y;
    return transpose(mat3(fx / p.z, 0.0, -fx * t.x / p.z,
                          0.0, fy / p.z, -fy * t.y / p.z,
                          0.0, 0.0, 0.0));
}

// Whether a camera-space centre is drawn: view z beyond the near plane, before any divide.
bool in_view(vec3 p) {
    return p.z > u_near;
}

// Depth of a camera-space centre for the sort and the depth layer: view z.
float view_depth(vec3 p) {
    return p.z;
}
