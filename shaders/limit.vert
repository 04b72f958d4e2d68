// Benchmark limit row, vertex stage: the quad path's own geometry (from quad_prepass.comp),
// placed with no per-splat math and no fragment inputs: per-primitive cost only.
// Twin: none (a benchmark's cost floor: quad_prepass.comp's quads placed as they are).
uniform vec2 u_viewport;  // (width, height) in pixels

layout(std430, binding = BINDING_PREPARED) readonly buffer Prepared { vec4 prepared[]; };

void main() {
    uint k = uint(gl_InstanceID);
    vec4 a = prepared[4u * k], b = prepared[4u * k + 1u];
    if (prepared[4u * k + 3u].z == 0.0) { gl_Position = vec4(0.0, 0.0, 2.0, 1.0); return; }
    vec2 corner = vec2((gl_VertexID & 1) != 0 ? 1.0 : -1.0, (gl_VertexID & 2) != 0 ? 1.0 : -1.0);
    vec2 pixel = a.xy + corner.x * a.zw + corner.y * b.xy;
    gl_Position = vec4(pixel / u_viewport * 2.0 - 1.0, 0.0, 1.0);
}
