// Catmull-Rom (bicubic, B = 0, C = 1/2) upscale of a premultiplied (C, A) draft frame to the
// framebuffer's size.  Texel rows map to framebuffer rows one to one (no flip): the source's
// row 0 and the target's row 0 are both the image's top.  Output pixel centre x + 1/2 samples
// the source at u = (x + 1/2) * src / dst - 1/2 texels; the four taps around it are clamped
// to the edge.  Ringing is clipped: alpha to [0, 1], colour to [0, inf).
// Twin: splatgl/interactive/upscale.py upscale().

layout(binding = UPSCALE_UNIT) uniform sampler2D u_source;
uniform vec2 u_ratio;          // source size / target size, per axis

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
    vec2 u = gl_FragCoord.xy * u_ratio - 0.5;
    vec2 base = floor(u);
    vec2 t = u - base;
    vec4 wx = catmull_rom_weights(t.x);
    vec4 wy = catmull_rom_weights(t.y);
    ivec2 b = ivec2(base) - 1;
    vec4 sum = vec4(0.0);
    for (int j = 0; j < 4; ++j) {
        int y = clamp(b.y + j, 0, last.y);
        vec4 row = wx.x * texelFetch(u_source, ivec2(clamp(b.x, 0, last.x), y), 0)
                 + wx.y * texelFetch(u_source, ivec2(clamp(b.x + 1, 0, last.x), y), 0)
                 + wx.z * texelFetch(u_source, ivec2(clamp(b.x + 2, 0, last.x), y), 0)
                 + wx.w * texelFetch(u_source, ivec2(clamp(b.x + 3, 0, last.x), y), 0);
        sum += wy[j] * row;
    }
    f_color = vec4(max(sum.rgb, 0.0), clamp(sum.a, 0.0, 1.0));
}
