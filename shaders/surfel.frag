// Quad path for 2DGS surfels, fragment stage: ray-splat intersection per pixel (2DGS eq. 8-10),
// the screen-space low pass (eq. 11, rho = min(rho_3d, F |x - c|^2)), the reference clamp and
// cut alpha = min(0.99, o exp(-rho / 2)), skipped below 1/255.  Premultiplied (c alpha, alpha)
// for front-to-back blending (ONE_MINUS_DST_ALPHA, ONE).
// Twin: splatgl/splatmath/surfel.py surfel_alpha().
// With DEPTH_OUTPUT a second target gets (z alpha, 0, 0, alpha), z the camera z of the hit;
// NORMAL_OUTPUT, UNDER and ORDERED_PASS as in quad.frag (with the hit's z).
#ifdef ORDERED_PASS
#include "lib/ordered_layers.glsl"
#endif
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
#ifdef NORMAL_OUTPUT
flat in vec3 v_normal;
#endif
#ifdef ORDERED_PASS
flat in uint v_index;
#else
layout(location = 0) out vec4 out_color;
#endif
#ifdef DEPTH_OUTPUT
layout(location = 1) out vec4 out_depth;
#endif
#ifdef NORMAL_OUTPUT
layout(location = NORMAL_OUTPUT) out vec4 out_normal;
#endif
#ifdef UNDER
layout(binding = UNDER_UNIT) uniform sampler2D u_under;  // geometry depth, +inf: none
#endif

void main() {
    vec2 d = gl_FragCoord.xy - v_center;
    float depth;
    float alpha = surfel_alpha(v_t0, v_t1, v_t2, v_depth_row, v_color.a, d, depth);
    // Skipped fragments write (0, 0, 0, 0), which the blend adds as exactly nothing: no
    // `discard`, which makes llvmpipe ignore early_fragment_tests (quad.frag).
    bool skip = alpha < ALPHA_MIN;
#ifdef UNDER
    skip = skip || depth >= texelFetch(u_under, ivec2(gl_FragCoord.xy), 0).r;
#endif
#ifdef ORDERED_PASS
    ordered_layers(skip, alpha, depth, v_index);
#else
    out_color = skip ? vec4(0.0) : vec4(v_color.rgb * alpha, alpha);
#ifdef DEPTH_OUTPUT
    out_depth = skip ? vec4(0.0) : vec4(depth * alpha, 0.0, 0.0, alpha);
#endif
#ifdef NORMAL_OUTPUT
    out_normal = skip ? vec4(0.0) : vec4(v_normal * alpha, alpha);
#endif
#endif
}
