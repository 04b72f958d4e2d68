// Per-splat screen setup shared by the quad path's vertex shader and its compute pre-pass.
// Twin: splatgl/splatmath/project.py project(), ellipse_axes(), reference_radius().
// Needs lib/camera.glsl, lib/scene.glsl, lib/project.glsl, lib/sh.glsl (and lib/normal.glsl)
// included before it.

struct ScreenSplat {
    vec2 mean2d;    // pixel position of the centre
    vec2 axis1;     // quad half-axes in pixels (columns of the corner transform)
    vec2 axis2;
    vec3 conic;     // (a, b, c) of Sigma'^-1
    vec3 color;     // SH colour
    float opacity;  // opacity (times the AA factor with ANTIALIAS)
    float depth;    // camera-space z of the centre
#ifdef NORMAL_OUTPUT
    vec3 normal;    // camera-space unit normal, towards the camera (lib/normal.glsl)
#endif
#ifdef ORDERED_RECT
    float radius;   // the reference's radius ceil(3 sqrt(lambda_max)), for its tile rectangle
#endif
};

// Quad half-axes by extent mode (DESIGN.md 2, splatgl.settings.QuadExtent):
//   default        opacity-aware ellipse axes, out to o exp(-r^2/2) = 1/255;
//   EXTENT_SQUARE  the reference's square of radius ceil(3 sqrt(lambda_max));
//   EXTENT_FAST    ellipse axes at a fixed FAST_CORNER_SIGMAS (the fragment then evaluates an
//                  identity conic on the interpolated corner coordinate).
void quad_axes(vec3 cov, float det, float opacity, out vec2 axis1, out vec2 axis2) {
#if defined(EXTENT_SQUARE)
    float r = reference_radius(cov);
    axis1 = vec2(r, 0.0);
    axis2 = vec2(0.0, r);
#elif defined(EXTENT_FAST)
    mat2 unit = ellipse_axes(cov, det, ALPHA_MIN * exp(0.5));  // k = 1: one sigma along each axis
    axis1 = unit[0] * FAST_CORNER_SIGMAS;
    axis2 = unit[1] * FAST_CORNER_SIGMAS;
#else
    mat2 axes = ellipse_axes(cov, det, opacity);
    axis1 = axes[0];
    axis2 = axes[1];
#endif
}

// Fills s for the splat of sorted entry idx (its index; with EQUIRECT the top bit marks the
// second copy of a splat on the +-180 degree seam, splatgl/cameras/equirect.py wrap_copies), its optical
// depth scaled by weight (1.0, or a level-of-detail blend weight in (0, 1]: opacity o drawn as
// 1 - (1 - o)^weight, splatgl/lod/cut.py); false when the splat is culled (behind the near
// plane, or a non-positive-definite 2D covariance).
bool setup_splat(uint idx, float weight, out ScreenSplat s) {
    uint i = idx & 0x7fffffffu;
    vec4 a = splat_mean_opacity(i);
    vec3 p = u_view_rot * a.xyz + u_view_trans;
#ifdef EQUIRECT
    p = eye_space(p);  // omni-directional stereo: the eye that sees this splat
#endif
    if (!in_view(p)) return false;  // view z (lens models: distance), before any divide
    mat3 rot = quat_to_rotmat(splat_rotation(i));
    vec3 scale = splat_scale(i);
    vec3 cov = covariance_2d(covariance_3d(rot, scale), p);
    float det = covariance_2d_det(cov, screen_factor(rot, scale, p));  // > 0 (see project.glsl)
    s.conic = conic(cov, det);
    if (!(det > 0.0)) return false;
    s.opacity = weight == 1.0 ? a.w : 1.0 - pow(1.0 - a.w, weight);
#ifdef ANTIALIAS
    s.opacity *= antialias_factor(cov);
#endif
    s.mean2d = project_mean(p);
#ifdef EQUIRECT
    // The seam copy sits one turn of longitude away, towards the other edge (lens.wrap_shift).
    if ((idx & 0x80000000u) != 0u)
        s.mean2d.x += s.mean2d.x < u_intrinsics.z ? u_wrap_period : -u_wrap_period;
#endif
    quad_axes(cov, det, s.opacity, s.axis1, s.axis2);
    s.depth = view_depth(p);
#ifdef NORMAL_OUTPUT
    s.normal = splat_normal(rot, scale, p);
#endif
#ifdef ORDERED_RECT
    s.radius = reference_radius(cov);
#endif
    s.color = sh_color(i, splat_sh_dc(i), normalize(a.xyz - u_cam_center));
    return true;
}
