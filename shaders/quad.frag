// Quad path, fragment stage: conic opacity with the reference clamp and cut, DESIGN.md 1-2:
//   alpha = min(0.99, o exp(power)), power = -0.5 (a dx^2 + c dy^2) - b dx dy,
//   skipped (written as (0, 0, 0, 0), which the blend adds as exactly nothing) when power > 0
//   or alpha < 1/255.  Output premultiplied (c alpha, alpha) for
//   front-to-back blending (ONE_MINUS_DST_ALPHA, ONE).
// Twin: splatgl/splatmath/blend.py splat_alpha(), blend_front_to_back().
// With DEPTH_OUTPUT, a second target gets (z alpha, 0, 0, alpha) under the same blend, so its
// own alpha channel tracks the same transmittance and red accumulates D = sum z alpha T; with
// NORMAL_OUTPUT the target at location NORMAL_OUTPUT gets (n alpha, alpha): N = sum n alpha T.
// With UNDER, a fragment at or behind the geometry's depth (u_under, in the splats' depth
// metric; splatgl/output/under.py) is skipped like one below 1/255.
// ORDERED_PASS: the median depth, count and top contributor instead (lib/ordered_layers.glsl).
#ifdef ORDERED_PASS
#include "lib/ordered_layers.glsl"
#endif
#if defined(EARLY_STOP) && !defined(COUNT_RASTERISED)
// Early termination: depth/stencil tests before shading, so fragments on pixels the mark pass
// stopped are never shaded.  The shader must not `discard` (llvmpipe then shades every fragment
// and tests late, whatever this layout says).  The benchmark's
// COUNT_RASTERISED variant leaves the tests late, so its counter sees every fragment rasterised,
// rejected ones included (the image is the same: the late test rejects the same fragments).
layout(early_fragment_tests) in;
#endif
flat in vec2 v_mean2d;
flat in vec3 v_conic;
flat in vec4 v_color;
flat in float v_depth;
#ifdef NORMAL_OUTPUT
flat in vec3 v_normal;
#endif
#ifdef ORDERED_PASS
flat in uint v_index;
flat in uvec4 v_rect;         // the reference's tile rectangle [min, max), tiles
#endif
#ifdef EXTENT_FAST
in vec2 v_unit;                // corner coordinate in sigmas
#endif

#ifndef ORDERED_PASS
layout(location = 0) out vec4 out_color;
#endif
#ifdef COUNT_FRAGMENTS
// Benchmark variant: counts fragments shaded (with COUNT_RASTERISED: rasterised) and fragments
// kept (alpha >= 1/255).
layout(std430, binding = BINDING_FRAGMENT_COUNTS) buffer FragmentCounts { uint fragments_shaded; uint fragments_kept; };
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
#ifdef EQUIRECT
uniform float u_wrap_period;  // pixels per turn of longitude: each copy reaches half a turn
#endif

void main() {
#ifdef COUNT_FRAGMENTS
    atomicAdd(fragments_shaded, 1u);
#endif
#ifdef EXTENT_FAST
    // The fast approximation: the quad spans a fixed FAST_CORNER_SIGMAS along the ellipse axes
    // and the conic in those coordinates is the identity.
    float power = -0.5 * dot(v_unit, v_unit);
#else
    vec2 d = gl_FragCoord.xy - v_mean2d;
    float power = -0.5 * (v_conic.x * d.x * d.x + v_conic.z * d.y * d.y) - v_conic.y * d.x * d.y;
#endif
    float alpha = min(ALPHA_MAX, v_color.a * exp(power));
    // Skipped fragments (power > 0 or alpha < 1/255) write (0, 0, 0, 0), which the blend adds
    // as exactly nothing.  No `discard`: llvmpipe ignores early_fragment_tests in a shader that
    // can discard, so early termination's rejected fragments were shaded all the same (2x the
    // cost per rejected fragment, docs/early-stop.md).
    bool skip = power > 0.0 || alpha < ALPHA_MIN;
#ifdef EQUIRECT
    // Half a turn of longitude each side of the centre (splatgl/cameras/equirect.py seam_period): a splat
    // at a pole spans the image once, and a seam splat's two copies never meet.
    skip = skip || abs(gl_FragCoord.x - v_mean2d.x) > 0.5 * u_wrap_period;
#endif
#ifdef UNDER
    skip = skip || v_depth >= texelFetch(u_under, ivec2(gl_FragCoord.xy), 0).r;
#endif
#ifdef ORDERED_PASS
    // The reference blends a splat only on the tiles of its rectangle (lib/tile_rect.glsl).
    uvec2 tile = uvec2(gl_FragCoord.xy) / uint(TILE_SIZE);
    skip = skip || any(lessThan(tile, v_rect.xy)) || any(greaterThanEqual(tile, v_rect.zw));
    ordered_layers(skip, alpha, v_depth, v_index);
#else
#ifdef COUNT_FRAGMENTS
    if (!skip) atomicAdd(fragments_kept, 1u);
#endif
    out_color = skip ? vec4(0.0) : vec4(v_color.rgb * alpha, alpha);
#ifdef DEPTH_OUTPUT
    out_depth = skip ? vec4(0.0) : vec4(v_depth * alpha, 0.0, 0.0, alpha);
#endif
#ifdef NORMAL_OUTPUT
    out_normal = skip ? vec4(0.0) : vec4(v_normal * alpha, alpha);
#endif
#endif
}
