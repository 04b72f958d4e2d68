// Benchmark limit row, fragment stage: a constant premultiplied colour under the quad path's
// blending, so the draw costs fill and blending only.
// Twin: none (a benchmark's cost floor: a constant colour, nothing to compare).
layout(location = 0) out vec4 out_color;

void main() {
    out_color = vec4(0.02, 0.02, 0.02, 0.02);
}
