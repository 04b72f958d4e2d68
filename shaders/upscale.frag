// Catmull-Rom (bicubic, B = 0, C = 1/2) upscale of a premultiplied (C, A) draft frame, one
// axis per pass: run along x into a (target width, source height) texture, then along y into
// the target (the same tensor-product filter as one 4x4 pass, at about a third of its taps).
// Texel rows map to framebuffer rows one to one (no flip): the source's row 0 and the target's
// row 0 are both the image's top.  Along the pass's axis, output pixel centre x + 1/2 samples
// the source at u = (x + 1/2) * src / dst - 1/2 texels; the four taps around it are clamped to
// the edge.  The second pass clips the ringing: alpha to [0, 1], colour to [0, inf).
// Twin: splatgl/splatmath/upscale.py upscale().

layout(binding = UPSCALE_UNIT) uniform sampler2D u_source;
uniform float u_ratio;         // source size / target size along the pass's axis
uniform int u_axis;            // 0: along x, 1: along y (the last pass: clip)

out vec4 f_color;

vec4 catmull_rom_weights(float t) {
    float t2 = t * t, t3 = t2 * t;
    return 0.5 * vec4(-t3 + 2.0 * t2 - t,
                      3.0 * t3 - 5.0 * t2 + 2.0,
                      -3.0 * t3 + 4.0 * t2 + t,
                      t3 - t2);
}

void main() {
    ivec2 last = textureSize(u_source, 0) - 1;
    ivec2 pixel = ivec2(gl_FragCoord.xy);
    float u = gl_FragCoord[u_axis] * u_ratio - 0.5;
    float base = floor(u);
    vec4 w = catmull_rom_weights(u - base);
    ivec2 step = u_axis == 0 ? ivec2(1, 0) : ivec2(0, 1);
    int b = int(base) - 1;
    vec4 sum = vec4(0.0);
    for (int j = 0; j < 4; ++j) {
        ivec2 p = pixel;
        p[u_axis] = clamp(b + j, 0, last[u_axis]);
        sum += w[j] * texelFetch(u_source, p, 0);
    }
    f_color = u_axis == 0 ? sum : vec4(max(sum.rgb, 0.0), clamp(sum.a, 0.0, 1.0));
}
