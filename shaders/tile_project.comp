// Tile renderer, stage 1 "project": one invocation per splat (3DGS preprocessCUDA).
// Twin: splatgl/reference/stages.py project().
// The math is lib/project.glsl's (its twin splatgl/splatmath/project.py).
// Culls view z <= near (before the divide), det(Sigma') <= 0, non-finite results and empty
// tile rectangles; writes the screen quantities, the tile rectangle and tiles_touched.
#include "lib/camera.glsl"
#include "lib/scene.glsl"
#include "lib/project.glsl"
#include "lib/sh.glsl"
#include "lib/tile_common.glsl"
#include "lib/normal.glsl"
#include "lib/tile_rect.glsl"
#ifdef SURFEL
#include "lib/surfel.glsl"
#endif
#ifdef PER_PIXEL
#include "lib/peak_depth.glsl"
#endif

layout(local_size_x = SPLAT_GROUP) in;

uniform uint u_count;   // number of splats N
uniform uvec2 u_grid;   // (tiles_x, tiles_y)

bool finite2(vec2 v) { return !any(isnan(v)) && !any(isinf(v)); }
bool finite3(vec3 v) { return !any(isnan(v)) && !any(isinf(v)); }

#ifdef SURFEL
// 2DGS surfels (twin: reference/stages.py project_surfels with splatgl/splatmath/surfel.py).  Culls the
// centre's view z <= near, o <= 1/255, an empty or non-finite box, non-finite colour or depth
// row and an empty tile rectangle; writes the centred rows (lib/tile_common.glsl, SURFEL).
void main() {
    uint i = splat_invocation();
    if (i >= u_count) return;
    tiles_touched[i] = 0u;
    proj_rect[i] = uvec4(0u);
    vec4 a = splat_mean_opacity(i);
    // p_c = R_cw p_w + t_cw (DESIGN.md 1); near cull on the centre's view z.
    vec3 p = u_view_rot * a.xyz + u_view_trans;
    if (!(p.z > u_near)) return;
    mat3 rot = quat_to_rotmat(splat_rotation(i));
    vec2 s = splat_scale(i).xy;
    vec3 a_u = u_view_rot * (rot[0] * s.x);   // camera-space s_u t_u (columns of W H, eq. 5)
    vec3 a_v = u_view_rot * (rot[1] * s.y);   // camera-space s_v t_v
    vec2 center;
    vec3 t0, t1, t2;
    surfel_screen(p, a_u, a_v, center, t0, t1, t2);   // centred T' = A P H
    vec2 lo, hi;
    // Box of the k-sigma ellipse (dual conic) united with the low-pass disc, clamped.
    if (!surfel_bounds(center, t0, t1, t2, a.w, lo, hi)) return;
    vec3 color = sh_color(i, splat_sh_dc(i), normalize(a.xyz - u_cam_center));
    vec3 depth_row = vec3(a_u.z, a_v.z, p.z);
    if (!finite3(color) || !finite3(depth_row)) return;
    // box_rect (reference/stages.py): box c +- h with c = (lo + hi) / 2, h = (hi - lo) / 2; in
    // pixel-index coordinates q = c - 0.5 it holds pixels ceil(q - h) .. floor(q + h), which
    // lie in tiles [floor(first / 16), floor(last / 16) + 1), clamped to the grid.
    vec2 box_c = 0.5 * (lo + hi);
    vec2 box_h = 0.5 * (hi - lo);
    vec2 q = box_c - 0.5;
    vec2 first = ceil(q - box_h);
    vec2 last = floor(q + box_h);
    if (any(lessThan(last, first))) return;   // no pixel centre in the box
    vec2 grid = vec2(u_grid);
    uvec2 rmin = uvec2(clamp(floor(first / float(TILE_SIZE)), vec2(0.0), grid));
    uvec2 rmax = uvec2(clamp(floor(last / float(TILE_SIZE)) + 1.0, vec2(0.0), grid));
    if (rmax.x <= rmin.x || rmax.y <= rmin.y) return;
    proj_mean_depth[i] = vec4(center, p.z, a.w);
    proj_conic_o[i] = vec4(t0.xy, t1.xy);
    proj_color[i] = vec4(color, 0.0);
    proj_surfel[i] = vec4(a_u.z, a_v.z, 0.0, 0.0);
#ifdef NORMAL_OUTPUT
    proj_normal[i] = vec4(surfel_normal(rot, p), 0.0);
#endif
    proj_rect[i] = uvec4(rmin, rmax);
    tiles_touched[i] = (rmax.x - rmin.x) * (rmax.y - rmin.y);
}
#else
void main() {
    uint i = splat_invocation();
    if (i >= u_count) return;
    tiles_touched[i] = 0u;
    proj_rect[i] = uvec4(0u);
    vec4 a = splat_mean_opacity(i);
    // p_c = R_cw p_w + t_cw (DESIGN.md 1); cull on view z before the perspective divide
    // (fisheye: distance and angle from the axis, lib/project.glsl in_view).
    vec3 p = u_view_rot * a.xyz + u_view_trans;
    if (!in_view(p)) return;
    // Sigma' = J W Sigma W^T J^T + 0.3 I (EWA, low-pass dilation).
    mat3 rot = quat_to_rotmat(splat_rotation(i));
    vec3 scale = splat_scale(i);
    vec3 cov = covariance_2d(covariance_3d(rot, scale), p);
    float det = covariance_2d_det(cov, screen_factor(rot, scale, p));  // > 0 (see project.glsl)
    vec3 con = conic(cov, det);
    if (!(det > 0.0)) return;
    float opacity = a.w;
#ifdef ANTIALIAS
    // o' = o sqrt(max(2.5e-5, det(Sigma') / det(Sigma' + 0.3 I))).
    opacity *= antialias_factor(cov);
#endif
    vec2 mean2d = project_mean(p);                      // u = fx x/z + cx, v = fy y/z + cy
    // c = max(sum h_lm Y_lm(d) + 0.5, 0), d = normalize(p_w - camera centre).
    vec3 color = sh_color(i, splat_sh_dc(i), normalize(a.xyz - u_cam_center));
    if (!finite2(mean2d) || !finite3(cov) || !finite3(con) || !finite3(color)
        || isnan(opacity) || isinf(opacity)) return;
    // Radius ceil(3 sqrt(lambda_max)); 3DGS getRect (lib/tile_rect.glsl).
    uvec4 rect = inria_tile_rect(mean2d, reference_radius(cov), vec2(u_grid));
    uvec2 rmin = rect.xy, rmax = rect.zw;
    uint touched = (rmax.x - rmin.x) * (rmax.y - rmin.y);
    if (touched == 0u) return;
    proj_mean_depth[i] = vec4(mean2d, view_depth(p), 0.0);
#ifdef PER_PIXEL
    peak_coefficients(u_view_rot, rot, scale, p, proj_peak[3u * i], proj_peak[3u * i + 1u],
                      proj_peak[3u * i + 2u]);
#endif
    proj_conic_o[i] = vec4(con, opacity);
    proj_color[i] = vec4(color, 0.0);
    proj_rect[i] = uvec4(rmin, rmax);
    tiles_touched[i] = touched;
#ifdef NORMAL_OUTPUT
    proj_normal[i] = vec4(splat_normal(rot, scale, p), 0.0);
#endif
}
#endif
