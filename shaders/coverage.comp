// Early termination (--early-stop auto), coverage estimate: how many fragments the sorted
// splats' quads will rasterise, before drawing them.  Each invocation sums, over the slots
// k = invocation, invocation + stride, ..., the area of quad k times the share of its screen
// rectangle inside the viewport (lib/camera.glsl visible_area; PREPARED: computed by the
// pre-pass), and writes its float sum to partial[invocation]; the caller adds the partial sums
// (no atomics, no barriers: both are slow on llvmpipe).
// Twin: splatgl/splatmath/early_stop.py coverage().
#include "lib/splat_rect.glsl"

layout(local_size_x = COVERAGE_GROUP) in;
layout(std430, binding = BINDING_COVERAGE) writeonly buffer Partial { float partial[]; };
#ifndef DEVICE_COUNT
uniform uint u_count;
#else
// The device-resident order (splatgl/renderers/early_stop_device.py): the kept count is in its
// draw command (dispatched indirectly, its size from stop_plan.comp).
layout(std430, binding = BINDING_DEVICE_COUNT) readonly buffer DeviceCount { uint device_command[]; };
#endif

void main() {
#ifdef DEVICE_COUNT
    uint count = device_command[1];
#else
    uint count = u_count;
#endif
    uint stride = gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    float sum = 0.0;
    for (uint k = gl_GlobalInvocationID.x; k < count; k += stride) {
#ifdef PREPARED
        sum += prepared[4u * k + 3u].w;   // quad_prepass.comp: visible_area, 0 when culled
#else
        vec2 lo, hi;
        uint value;
        float area;
        if (splat_rect(k, lo, hi, value, area)) sum += visible_area(lo, hi, area);
#endif
    }
    partial[gl_GlobalInvocationID.x] = sum;
}
