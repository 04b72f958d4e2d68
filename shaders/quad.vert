// Quad path, vertex stage: one instance per visible splat, 4 vertices (triangle strip).
// Evaluates SH colour and the EWA 2D covariance, and sizes a camera-facing quad.
// Twin: splatgl/splatmath/project.py project(), ellipse_axes(), reference_radius().
#include "lib/camera.glsl"
#include "lib/scene.glsl"
#include "lib/project.glsl"
#include "lib/sh.glsl"
#include "lib/normal.glsl"
#include "lib/splat_setup.glsl"
#include "lib/tile_rect.glsl"
#include "lib/quad_emit.glsl"

in uint splat_index;          // from the per-view sorted index buffer (divisor 1)

void main() {
    ScreenSplat s;
    if (!setup_splat(splat_index, 1.0, s)) { gl_Position = CULLED; return; }
    emit_corner(s.mean2d, s.axis1, s.axis2, s.conic, s.color, s.opacity, s.depth);
#ifdef NORMAL_OUTPUT
    v_normal = s.normal;
#endif
#ifdef ORDERED_PASS
    v_index = splat_index & 0x7fffffffu;   // a seam copy (EQUIRECT) names its original
    v_rect = inria_tile_rect(s.mean2d, s.radius, ceil(u_viewport / float(TILE_SIZE)));
#endif
}
