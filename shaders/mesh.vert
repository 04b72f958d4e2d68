// Mesh renderer, vertex stage: camera-space corners (transformed in float64 on the CPU) to clip
// space with the camera's own pixel mapping, no y flip (as the splats: framebuffer row 0 is
// image row 0, so gl_FragCoord.xy = (j + 0.5, i + 0.5)).
//   perspective:  u = fx x / z + cx  ->  clip = (2 (fx x + cx z) / W - z, ..., a z + b, z)
//   orthographic: u = fx x + cx      ->  clip = (2 (fx x + cx) / W - 1, ..., a z + b, 1)
// with a, b mapping [u_near, u_far] to the depth range (hidden surfaces only: the depth layer
// is the interpolated view z, exact at the pixel centre since z is linear on a triangle).
// Twin: splatgl/splatmath/mesh.py ray_depth().
in vec3 in_pos;      // camera space
in vec3 in_color;    // face colour, shaded
out float v_z;
flat out vec3 v_color;

uniform vec4 u_intrinsics;   // (fx, fy, cx, cy)
uniform vec2 u_viewport;     // (W, H)
uniform vec2 u_depth_map;    // (a, b)

void main() {
    vec3 p = in_pos;
#ifdef ORTHOGRAPHIC
    vec2 pixel = u_intrinsics.xy * p.xy + u_intrinsics.zw;
    gl_Position = vec4(2.0 * pixel / u_viewport - 1.0, u_depth_map.x * p.z + u_depth_map.y, 1.0);
#else
    vec2 pixel_z = u_intrinsics.xy * p.xy + u_intrinsics.zw * p.z;   // pixel times z
    gl_Position = vec4(2.0 * pixel_z / u_viewport - p.z, u_depth_map.x * p.z + u_depth_map.y, p.z);
#endif
    v_z = p.z;
    v_color = in_color;
}
