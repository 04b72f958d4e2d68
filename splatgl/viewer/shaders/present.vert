#version 430 core
// A single triangle covering the viewport (no vertex buffer): uv runs 0..1 over the viewport,
// uv.y = 0 at the bottom (GL window convention).
// Twin: none (a full-screen triangle).
out vec2 v_uv;

void main() {
    vec2 p = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));  // (0,0) (2,0) (0,2)
    v_uv = p;
    gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}
