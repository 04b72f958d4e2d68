// Quad path, vertex stage: one instance per visible splat, 4 vertices (triangle strip).
// Evaluates SH colour and the EWA 2D covariance, and sizes a camera-facing quad.
// Twin: splatgl/project.py project() + ellipse_axes / reference_radius.
#include "lib/camera.glsl"
#include "lib/scene.glsl"
#include "lib/project.glsl"
#include "lib/sh.glsl"

in uint splat_index;          // from the per-view sorted index buffer (divisor 1)

flat out vec2 v_mean2d;       // pixel centre of the splat
flat out vec3 v_conic;        // (a, b, c) of Sigma'^-1
flat out vec4 v_color;        // (SH colour, opacity)
flat out float v_depth;       // camera-space z of the centre, for the depth layer

const vec4 CULLED = vec4(0.0, 0.0, 2.0, 1.0);  // outside the clip volume: nothing rasterised

void main() {
    uint i = splat_index;
    vec4 a = splat_a[i];
    vec3 p = u_view_rot * a.xyz + u_view_trans;
    if (p.z <= u_near) { gl_Position = CULLED; return; }  // view z before the divide
    vec3 cov = covariance_2d(covariance_3d(quat_to_rotmat(splat_q[i]), splat_s[i].xyz), p);
    float det;
    vec3 con = conic(cov, det);
    if (!(det > 0.0)) { gl_Position = CULLED; return; }
    float opacity = a.w;
#ifdef ANTIALIAS
    opacity *= antialias_factor(cov);
#endif
    vec2 mean2d = project_mean(p);
    vec2 corner = vec2((gl_VertexID & 1) != 0 ? 1.0 : -1.0, (gl_VertexID & 2) != 0 ? 1.0 : -1.0);
#ifdef EXTENT_SQUARE
    vec2 pixel = mean2d + corner * reference_radius(cov);
#else
    vec2 pixel = mean2d + ellipse_axes(cov, opacity) * corner;
#endif
    // Image coordinates map to NDC without a y flip: framebuffer row 0 holds image row 0 (the
    // top), so a plain readback is already top-down and gl_FragCoord.xy = (j + 0.5, i + 0.5).
    gl_Position = vec4(pixel / u_viewport * 2.0 - 1.0, 0.0, 1.0);
    v_mean2d = mean2d;
    v_conic = con;
    v_depth = p.z;
    vec3 dir = normalize(a.xyz - u_cam_center);
    v_color = vec4(sh_color(i, splat_dc[i].rgb, dir), opacity);
}
