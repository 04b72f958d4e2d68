// Early termination, mark pass (vertex stage): one full-screen triangle at NDC z = -1, so the
// depth it writes is 0 and every later splat quad (NDC z = 0, depth 0.5) fails the LESS test
// there.  Drawn with 3 vertices and no attributes.
// Twin: none (a full-screen triangle; the mark's test is stop_mark.frag's).
void main() {
    vec2 p = vec2(float((gl_VertexID & 1) << 2) - 1.0, float((gl_VertexID & 2) << 1) - 1.0);
    gl_Position = vec4(p, -1.0, 1.0);
}
