// Orthographic camera model (ORTHOGRAPHIC is defined too).  fx, fy in pixels per world unit.
// Twin: splatgl/cameras/orthographic.py Orthographic.project(), Orthographic.jacobian(),
//   Orthographic.visible(), Orthographic.depth().

// Pixel position of a camera-space point: u = fx x + cx.
vec2 project_mean(vec3 p) {
    return u_intrinsics.xy * p.xy + u_intrinsics.zw;
}

// Constant Jacobian diag(fx, fy), in the pinhole's layout (rows of J in the first two rows).
mat3 jacobian(vec3 p) {
    return transpose(mat3(u_intrinsics.x, 0.0, 0.0, 0.0, u_intrinsics.y, 0.0, 0.0, 0.0, 0.0));
}

// Whether a camera-space centre is drawn: view z beyond the near plane.
bool in_view(vec3 p) {
    return p.z > u_near;
}

// Depth for the sort and the depth layer: view z.
float view_depth(vec3 p) {
    return p.z;
}
