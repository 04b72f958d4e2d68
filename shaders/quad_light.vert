// Quad path, light vertex stage: instance k reads what quad_prepass.comp computed for the k-th
// sorted splat and only places the corner.  Slot k is u_base + gl_InstanceID for a plain range
// draw; with SURVIVORS (early termination) it comes from the occlusion cull's compacted list.
// Twin: splatgl/splatmath/project.py project(), ellipse_axes().
#include "lib/camera.glsl"
#include "lib/quad_emit.glsl"
#include "lib/tile_rect.glsl"

layout(std430, binding = BINDING_PREPARED) readonly buffer Prepared { vec4 prepared[]; };
#ifdef NORMAL_OUTPUT
layout(std430, binding = BINDING_PREPARED_NORMAL) readonly buffer PreparedNormal { vec4 prepared_normal[]; };
#endif
#ifdef ORDERED_PASS
layout(std430, binding = BINDING_ORDER) readonly buffer Order { uint order[]; };
layout(std430, binding = BINDING_PREPARED_RADIUS) readonly buffer PreparedRadius { float prepared_radius[]; };
#endif
#ifdef SURVIVORS
in uint splat_slot;           // survivors[baseInstance + instance] (occlusion_cull.comp)
#else
uniform uint u_base;          // first slot of this draw (batched draws)
#endif

void main() {
#ifdef SURVIVORS
    uint k = splat_slot;
#else
    uint k = u_base + uint(gl_InstanceID);
#endif
    vec4 d = prepared[4u * k + 3u];
    if (d.z == 0.0) { gl_Position = CULLED; return; }
    vec4 a = prepared[4u * k], b = prepared[4u * k + 1u], c = prepared[4u * k + 2u];
    emit_corner(a.xy, a.zw, b.xy, vec3(b.zw, c.x), c.yzw, d.x, d.y);
#ifdef NORMAL_OUTPUT
    v_normal = prepared_normal[k].xyz;
#endif
#ifdef ORDERED_PASS
    v_index = order[k] & 0x7fffffffu;      // a seam copy (EQUIRECT) names its original
    v_rect = inria_tile_rect(a.xy, prepared_radius[k], ceil(u_viewport / float(TILE_SIZE)));
#endif
}
