// The screen rectangle of a sorted splat's quad, for the passes that reason about quads
// without drawing them (occlusion_cull.comp, coverage.comp).  Variants: PREPARED (3DGS after
// quad_prepass.comp, read from `prepared`), SURFEL (2DGS, the box of surfel.vert), neither (the
// 3DGS vertex path, the setup of quad.vert).  Binds Order and, with PREPARED, Prepared.
// Twin: splatgl/splatmath/project.py ellipse_axes(); splatgl/splatmath/surfel.py surfel_bounds().
#include "lib/camera.glsl"
#include "lib/scene.glsl"
#include "lib/project.glsl"
#ifdef SURFEL
#include "lib/surfel.glsl"
#elif !defined(PREPARED)
#include "lib/sh.glsl"
#include "lib/normal.glsl"
#include "lib/splat_setup.glsl"
#endif

layout(std430, binding = BINDING_ORDER) readonly buffer Order { uint order[]; };
#ifdef PREPARED
layout(std430, binding = BINDING_PREPARED) readonly buffer Prepared { vec4 prepared[]; };
#endif

// Pixel rectangle [lo, hi] containing the splat's quad, the value a survivor stores, and the
// quad's area in pixels (the parallelogram mean +- axis1 +- axis2, 4 |axis1 x axis2|; the box
// for surfels).  False: the splat draws nothing (culled by its own setup).
bool splat_rect(uint k, out vec2 lo, out vec2 hi, out uint value, out float area) {
#ifdef PREPARED
    value = k;
    vec4 d = prepared[4u * k + 3u];
    if (d.z == 0.0) return false;
    vec4 a = prepared[4u * k], b = prepared[4u * k + 1u];
    vec2 half_size = abs(a.zw) + abs(b.xy);   // corners mean +- axis1 +- axis2
    lo = a.xy - half_size;
    hi = a.xy + half_size;
    area = 4.0 * abs(a.z * b.y - a.w * b.x);
    return true;
#elif defined(SURFEL)
    uint i = order[k];
    value = i;
    vec4 a = splat_mean_opacity(i);
    vec3 p = u_view_rot * a.xyz + u_view_trans;
    if (p.z <= u_near) return false;
    mat3 rot = quat_to_rotmat(splat_rotation(i));
    vec2 s = splat_scale(i).xy;
    vec2 center;
    vec3 t0, t1, t2;
    surfel_screen(p, u_view_rot * (rot[0] * s.x), u_view_rot * (rot[1] * s.y), center, t0, t1, t2);
    bool ok = surfel_bounds(center, t0, t1, t2, a.w, lo, hi);
    area = (hi.x - lo.x) * (hi.y - lo.y);
    return ok;
#else
    uint i = order[k];
    value = i;
    ScreenSplat s;
    if (!setup_splat(i, 1.0, s)) return false;
    vec2 half_size = abs(s.axis1) + abs(s.axis2);
    lo = s.mean2d - half_size;
    hi = s.mean2d + half_size;
    area = 4.0 * abs(s.axis1.x * s.axis2.y - s.axis1.y * s.axis2.x);
    return true;
#endif
}

