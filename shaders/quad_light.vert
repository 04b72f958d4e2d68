// Quad path, light vertex stage: instance k reads what quad_prepass.comp computed for the k-th
// sorted splat and only places the corner.
#include "lib/camera.glsl"
#include "lib/quad_emit.glsl"

layout(std430, binding = 6) readonly buffer Prepared { vec4 prepared[]; };

void main() {
    uint k = uint(gl_InstanceID);
    vec4 d = prepared[4u * k + 3u];
    if (d.z == 0.0) { gl_Position = CULLED; return; }
    vec4 a = prepared[4u * k], b = prepared[4u * k + 1u], c = prepared[4u * k + 2u];
    emit_corner(a.xy, a.zw, b.xy, vec3(b.zw, c.x), c.yzw, d.x, d.y);
}
