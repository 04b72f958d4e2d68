// Quad path for 2DGS surfels, vertex stage: one instance per visible surfel, 4 vertices
// (triangle strip).  Builds the centred T = P H (2DGS eq. 5), sizes the quad to the screen box
// of the k-sigma ellipse and the low-pass disc, and evaluates SH colour.
// Twin: splatgl/splatmath/surfel.py surfel_screen(), surfel_bounds().
#include "lib/camera.glsl"
#include "lib/scene.glsl"
#include "lib/project.glsl"
#include "lib/sh.glsl"
#include "lib/surfel.glsl"
#include "lib/normal.glsl"

in uint splat_index;          // from the per-view sorted index buffer (divisor 1)

flat out vec2 v_center;       // projected centre c (pixels), the low-pass centre
flat out vec3 v_t0;           // centred T'_0 = T_0 - c_x T_2 (third entry 0)
flat out vec3 v_t1;           // centred T'_1 = T_1 - c_y T_2 (third entry 0)
flat out vec3 v_t2;           // T_2
flat out vec3 v_depth_row;    // view z of (u, v, 1): (a_u.z, a_v.z, p.z)
flat out vec4 v_color;        // (SH colour, opacity)
#ifdef NORMAL_OUTPUT
flat out vec3 v_normal;       // camera-space unit normal, towards the camera
#endif
#ifdef ORDERED_PASS
flat out uint v_index;        // the surfel's scene row
#endif

const vec4 CULLED = vec4(0.0, 0.0, 2.0, 1.0);  // outside the clip volume: nothing rasterised

void main() {
    uint i = splat_index;
    vec4 a = splat_mean_opacity(i);
    vec3 p = u_view_rot * a.xyz + u_view_trans;
    if (p.z <= u_near) { gl_Position = CULLED; return; }  // view z of the centre, before the divide
    mat3 rot = quat_to_rotmat(splat_rotation(i));
    vec2 s = splat_scale(i).xy;
    vec3 a_u = u_view_rot * (rot[0] * s.x);  // camera-space s_u t_u
    vec3 a_v = u_view_rot * (rot[1] * s.y);  // camera-space s_v t_v
    vec2 center;
    vec3 t0, t1, t2;
    surfel_screen(p, a_u, a_v, center, t0, t1, t2);
    vec2 lo, hi;
    if (!surfel_bounds(center, t0, t1, t2, a.w, lo, hi)) { gl_Position = CULLED; return; }
    vec2 corner = vec2(float(gl_VertexID & 1), float((gl_VertexID >> 1) & 1));
    vec2 pixel = mix(lo, hi, corner);
    // Image coordinates map to NDC without a y flip (see quad.vert): gl_FragCoord.xy are the
    // pixel centres (j + 0.5, i + 0.5) with row 0 at the top.
    gl_Position = vec4(pixel / u_viewport * 2.0 - 1.0, 0.0, 1.0);
    v_center = center;
    v_t0 = t0;
    v_t1 = t1;
    v_t2 = t2;
    v_depth_row = vec3(a_u.z, a_v.z, p.z);
    vec3 dir = normalize(a.xyz - u_cam_center);
    v_color = vec4(sh_color(i, splat_sh_dc(i), dir), a.w);
#ifdef NORMAL_OUTPUT
    v_normal = surfel_normal(rot, p);
#endif
#ifdef ORDERED_PASS
    v_index = i;
#endif
}
