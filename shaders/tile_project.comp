// Tile renderer, stage 1 "project": one invocation per splat (3DGS preprocessCUDA).
// Twin: splatgl/reference/stages.py project() (math in splatgl/project.py / lib/project.glsl).
// Culls view z <= near (before the divide), det(Sigma') <= 0, non-finite results and empty
// tile rectangles; writes the screen quantities, the tile rectangle and tiles_touched.
#include "lib/camera.glsl"
#include "lib/scene.glsl"
#include "lib/project.glsl"
#include "lib/sh.glsl"
#include "lib/tile_common.glsl"

layout(local_size_x = SPLAT_GROUP) in;

uniform uint u_count;   // number of splats N
uniform uvec2 u_grid;   // (tiles_x, tiles_y)

bool finite2(vec2 v) { return !any(isnan(v)) && !any(isinf(v)); }
bool finite3(vec3 v) { return !any(isnan(v)) && !any(isinf(v)); }

void main() {
    uint i = splat_invocation();
    if (i >= u_count) return;
    tiles_touched[i] = 0u;
    proj_rect[i] = uvec4(0u);
    vec4 a = splat_a[i];
    // p_c = R_cw p_w + t_cw (DESIGN.md 1); cull on view z before the perspective divide.
    vec3 p = u_view_rot * a.xyz + u_view_trans;
    if (!(p.z > u_near)) return;
    // Sigma' = J W Sigma W^T J^T + 0.3 I (EWA, low-pass dilation).
    vec3 cov = covariance_2d(covariance_3d(quat_to_rotmat(splat_q[i]), splat_s[i].xyz), p);
    float det;
    vec3 con = conic(cov, det);
    if (!(det > 0.0)) return;
    float opacity = a.w;
#ifdef ANTIALIAS
    // o' = o sqrt(max(2.5e-5, det(Sigma') / det(Sigma' + 0.3 I))).
    opacity *= antialias_factor(cov);
#endif
    vec2 mean2d = project_mean(p);                      // u = fx x/z + cx, v = fy y/z + cy
    // c = max(sum h_lm Y_lm(d) + 0.5, 0), d = normalize(p_w - camera centre).
    vec3 color = sh_color(i, splat_dc[i].rgb, normalize(a.xyz - u_cam_center));
    if (!finite2(mean2d) || !finite3(cov) || !finite3(con) || !finite3(color)
        || isnan(opacity) || isinf(opacity)) return;
    // Radius ceil(3 sqrt(lambda_max)); 3DGS getRect on p = mean2d - 0.5 (pixel-index
    // coordinates): min = clamp(int((p - r) / 16), 0, grid), max = clamp(int((p + r + 15) / 16),
    // 0, grid), truncation toward zero (clamped as floats so huge values cannot overflow int).
    float r = reference_radius(cov);
    vec2 pp = mean2d - 0.5;
    vec2 grid = vec2(u_grid);
    uvec2 rmin = uvec2(clamp(trunc((pp - r) / float(TILE_SIZE)), vec2(0.0), grid));
    uvec2 rmax = uvec2(clamp(trunc((pp + r + float(TILE_SIZE - 1)) / float(TILE_SIZE)), vec2(0.0), grid));
    uint touched = (rmax.x - rmin.x) * (rmax.y - rmin.y);
    if (touched == 0u) return;
    proj_mean_depth[i] = vec4(mean2d, p.z, 0.0);
    proj_conic_o[i] = vec4(con, opacity);
    proj_color[i] = vec4(color, 0.0);
    proj_rect[i] = uvec4(rmin, rmax);
    tiles_touched[i] = touched;
}
