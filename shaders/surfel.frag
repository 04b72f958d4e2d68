// Quad path for 2DGS surfels, fragment stage: ray-splat intersection per pixel (2DGS eq. 8-10),
// the screen-space low pass (eq. 11, rho = min(rho_3d, F |x - c|^2)), the reference clamp and
// cut alpha = min(0.99, o exp(-rho / 2)), skipped below 1/255.  Premultiplied (c alpha, alpha)
// for front-to-back blending (ONE_MINUS_DST_ALPHA, ONE).
// Twin: splatgl/twins/surfel.py surfel_alpha().
// With DEPTH_OUTPUT a second target gets (z alpha, 0, 0, alpha), z the camera z of the hit.
#include "lib/camera.glsl"
#include "lib/surfel.glsl"

#ifdef EARLY_STOP
// Early termination: depth/stencil tests before shading, so fragments on pixels the mark pass
// stopped are never shaded (the shader must not `discard`: see quad.frag).
layout(early_fragment_tests) in;
#endif
flat in vec2 v_center;
flat in vec3 v_t0;
flat in vec3 v_t1;
flat in vec3 v_t2;
flat in vec3 v_depth_row;
flat in vec4 v_color;

layout(location = 0) out vec4 out_color;
#ifdef DEPTH_OUTPUT
layout(location = 1) out vec4 out_depth;
#endif

void main() {
    vec2 d = gl_FragCoord.xy - v_center;
    float depth;
    float alpha = surfel_alpha(v_t0, v_t1, v_t2, v_depth_row, v_color.a, d, depth);
    // Skipped fragments write (0, 0, 0, 0), which the blend adds as exactly nothing: no
    // `discard`, which makes llvmpipe ignore early_fragment_tests (quad.frag).
    bool skip = alpha < ALPHA_MIN;
    out_color = skip ? vec4(0.0) : vec4(v_color.rgb * alpha, alpha);
#ifdef DEPTH_OUTPUT
    out_depth = skip ? vec4(0.0) : vec4(depth * alpha, 0.0, 0.0, alpha);
#endif
}
