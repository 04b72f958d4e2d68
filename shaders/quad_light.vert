// Quad path, light vertex stage: instance k reads what quad_prepass.comp computed for the k-th
// sorted splat and only places the corner.  Slot k is u_base + gl_InstanceID for a plain range
// draw; with PIECES (early termination) it comes with the piece to draw from the occlusion
// cull's compacted list.
#include "lib/camera.glsl"
#include "lib/quad_emit.glsl"

layout(std430, binding = 6) readonly buffer Prepared { vec4 prepared[]; };
#ifdef PIECES
in uvec3 splat_piece;         // (slot, piece) = pieces[baseInstance + instance] (occlusion_cull.comp)
#else
uniform uint u_base;          // first slot of this draw (batched draws)
#endif

void main() {
#ifdef PIECES
    uint k = splat_piece.x;
    uvec2 piece = splat_piece.yz;
#else
    uint k = u_base + uint(gl_InstanceID);
    uvec2 piece = uvec2(WHOLE_PIECE, 0u);
#endif
    vec4 d = prepared[4u * k + 3u];
    if (d.z == 0.0) { gl_Position = CULLED; return; }
    vec4 a = prepared[4u * k], b = prepared[4u * k + 1u], c = prepared[4u * k + 2u];
    emit_piece(a.xy, a.zw, b.xy, vec3(b.zw, c.x), c.yzw, d.x, d.y, piece);
}
