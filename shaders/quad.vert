// Quad path, vertex stage: one instance per visible splat, 4 vertices (triangle strip).
// Evaluates SH colour and the EWA 2D covariance, and sizes a camera-facing quad.
// Twin: splatgl/project.py project() + ellipse_axes / reference_radius.
#include "lib/camera.glsl"
#include "lib/scene.glsl"
#include "lib/project.glsl"
#include "lib/sh.glsl"
#include "lib/splat_setup.glsl"
#include "lib/quad_emit.glsl"

#ifdef PIECES
in uvec3 splat_piece;         // (splat index, piece) from occlusion_cull.comp (divisor 1)
#else
in uint splat_index;          // from the per-view sorted index buffer (divisor 1)
#endif

void main() {
#ifdef PIECES
    uint i = splat_piece.x;
    uvec2 piece = splat_piece.yz;
#else
    uint i = splat_index;
    uvec2 piece = uvec2(WHOLE_PIECE, 0u);
#endif
    ScreenSplat s;
    if (!setup_splat(i, s)) { gl_Position = CULLED; return; }
    emit_piece(s.mean2d, s.axis1, s.axis2, s.conic, s.color, s.opacity, s.depth, piece);
}
