// The quad path's ordered pass (ORDERED_PASS): the layers that follow the running
// transmittance with a threshold (median depth, count, top contributor), which no blend
// equation computes.  The pass draws the same sorted quads again into two targets that the
// fragment stage reads and writes itself through GL_EXT_shader_framebuffer_fetch, whose reads
// are coherent and in primitive order: every pixel sees its splats front to back, exactly as
// the reference's loop does, and applies the reference's rules (DESIGN.md 2; a 3DGS fragment
// outside the reference's tile rectangle, lib/tile_rect.glsl, counts as skipped):
//   skipped (alpha < 1/255, or behind the geometry) and after the stop: nothing;
//   stop, without counting the splat, once T (1 - alpha) < 1e-4;
//   median z = the splat's z while T > MEDIAN_T (T before it);
//   top = the first splat with the largest w = alpha T;  count += 1;  T *= 1 - alpha.
// ordered_f = (T, median z, top weight, 0), cleared to (1, 0, 0, 0);
// ordered_u = (count, top index + 1, stopped, 0), cleared to 0.
// Twin: splatgl/reference/layers.py BatchLayers.add().
// Include it first in the fragment stage (the #extension line precedes every other token).
#extension GL_EXT_shader_framebuffer_fetch : require

layout(location = 0) inout vec4 ordered_f;
layout(location = 1) inout uvec4 ordered_u;

void ordered_layers(bool skip, float alpha, float z, uint index) {
    vec4 f = ordered_f;
    uvec4 u = ordered_u;
    if (skip || u.z != 0u) return;
    float test_t = f.x * (1.0 - alpha);
    if (test_t < T_MIN) {
        ordered_u = uvec4(u.xy, 1u, 0u);
        return;
    }
    float w = alpha * f.x;
    if (f.x > MEDIAN_T) f.y = z;
    if (w > f.z) {
        f.z = w;
        u.y = index + 1u;
    }
    u.x += 1u;
    f.x = test_t;
    ordered_f = f;
    ordered_u = u;
}
