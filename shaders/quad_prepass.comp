// Quad path, compute pre-pass: the per-splat math of quad.vert done once per splat (not once
// per corner), for the sorted visible splats, into `prepared` for quad_light.vert.
// Layout per sorted slot k (4 vec4): (mean2d, axis1), (axis2, conic.ab), (conic.c, color),
// (opacity, depth, visible, fragments in the viewport: camera.glsl visible_area).  With
// OPACITY_WEIGHT, the scene with those opacities scaled (a level-of-detail cut's blend).
// Twin: splatgl/splatmath/project.py project(), ellipse_axes(), reference_radius();
//   splatgl/lod/selection.py blended_scene().
#include "lib/camera.glsl"
#include "lib/scene.glsl"
#include "lib/project.glsl"
#include "lib/sh.glsl"
#include "lib/normal.glsl"
#include "lib/splat_setup.glsl"

layout(local_size_x = PREPASS_GROUP) in;
#include "lib/dispatch.glsl"
layout(std430, binding = BINDING_ORDER) readonly buffer Order { uint order[]; };
layout(std430, binding = BINDING_PREPARED) writeonly buffer Prepared { vec4 prepared[]; };
#ifdef NORMAL_OUTPUT
// The normal layer: slot k's camera-space normal (lib/normal.glsl), for quad_light.vert.
layout(std430, binding = BINDING_PREPARED_NORMAL) writeonly buffer PreparedNormal { vec4 prepared_normal[]; };
#endif
#ifdef ORDERED_RECT
// The ordered pass: slot k's reference radius, for its tile rectangle (lib/tile_rect.glsl).
layout(std430, binding = BINDING_PREPARED_RADIUS) writeonly buffer PreparedRadius { float prepared_radius[]; };
#endif
#ifdef OPACITY_WEIGHT
// Level-of-detail blend: a factor on each sorted slot's opacity (splatgl/lod/selection.py).
layout(std430, binding = BINDING_OPACITY_WEIGHT) readonly buffer OpacityWeight { float opacity_weight[]; };
#endif
uniform uint u_count;
uniform uint u_first;   // slot of invocation 0 (a long pre-pass runs in chunks, polled between)
#ifdef DEVICE_COUNT
// The device-resident order (splatgl/renderers/quad_device.py): the slots to prepare are the
// kept count in its draw command (dispatched indirectly from the same buffer).
layout(std430, binding = BINDING_DEVICE_COUNT) readonly buffer DeviceCount { uint device_command[]; };
#endif

void main() {
    uint k = u_first + linear_invocation();
#ifdef DEVICE_COUNT
    if (k >= device_command[1]) return;
#else
    if (k >= u_count) return;
#endif
    ScreenSplat s;
#ifdef OPACITY_WEIGHT
    bool ok = setup_splat(order[k], opacity_weight[k], s);
#else
    bool ok = setup_splat(order[k], 1.0, s);
#endif
    if (!ok) {
        prepared[4u * k + 3u] = vec4(s.opacity, s.depth, 0.0, 0.0);
        return;
    }
    vec2 half_size = abs(s.axis1) + abs(s.axis2);
    float area = 4.0 * abs(s.axis1.x * s.axis2.y - s.axis1.y * s.axis2.x);
    prepared[4u * k + 3u] = vec4(s.opacity, s.depth, 1.0,
                                 visible_area(s.mean2d - half_size, s.mean2d + half_size, area));
    prepared[4u * k] = vec4(s.mean2d, s.axis1);
    prepared[4u * k + 1u] = vec4(s.axis2, s.conic.xy);
    prepared[4u * k + 2u] = vec4(s.conic.z, s.color);
#ifdef NORMAL_OUTPUT
    prepared_normal[k] = vec4(s.normal, 0.0);
#endif
#ifdef ORDERED_RECT
    prepared_radius[k] = s.radius;
#endif
}
