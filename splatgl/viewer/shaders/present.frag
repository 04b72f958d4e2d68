#version 430 core
// Shows an image whose texture row 0 is the image's top row (an offscreen target's row 0, or
// an uploaded NumPy image): sample at t = 1 - uv.y so the top lands at the top of the window.
//   MODE_PREMULTIPLIED: the quad path's raw target (C, A): output C + (1 - A) background
//                       (DESIGN.md section 3), so the window's own alpha never matters.
//   MODE_OPAQUE:        an image already composited: output its RGB.
//   MODE_OVERLAY:       straight-alpha RGBA drawn with (SRC_ALPHA, ONE_MINUS_SRC_ALPHA).
// The MODE_* values are defines from splatgl/viewer/present.py Mode.
// Twin: splatgl/renderers/quad.py composite().

layout(binding = PRESENT_UNIT) uniform sampler2D u_image;
uniform vec3 u_background;
uniform int u_mode;

in vec2 v_uv;
out vec4 f_color;

void main() {
    vec4 c = texture(u_image, vec2(v_uv.x, 1.0 - v_uv.y));
    if (u_mode == MODE_PREMULTIPLIED) {
        f_color = vec4(clamp(c.rgb + (1.0 - c.a) * u_background, 0.0, 1.0), 1.0);
    } else if (u_mode == MODE_OPAQUE) {
        f_color = vec4(clamp(c.rgb, 0.0, 1.0), 1.0);
    } else {
        f_color = c;
    }
}
