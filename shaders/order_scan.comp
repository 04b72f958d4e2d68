// Device-resident order, step 2 of 3 (splatgl/renderers/quad_device.py): one work group turns
// the kept count of each of order_cull.comp's u_blocks work groups into that group's first
// slot (an exclusive scan, in place), writes the total into the indirect draw command's
// instance count and the pre-pass's dispatch size after it (a group of PREPASS_GROUP slots).
// Each thread scans a run of consecutive groups; thread 0 scans the runs' sums.
// Twin: splatgl/order/cull.py cull_visible().

layout(local_size_x = ORDER_SCAN_GROUP) in;
#include "lib/dispatch.glsl"
layout(std430, binding = ORDER_BINDING_BLOCKS) buffer Blocks { uint blocks[]; };
layout(std430, binding = ORDER_BINDING_COMMAND) buffer Command { uint command[]; };

uniform uint u_blocks;
uniform uint u_group_limit;   // the pre-pass dispatch's split (splatgl/gl/dispatch.py)

shared uint sums[ORDER_SCAN_GROUP];

void main() {
    uint t = gl_LocalInvocationIndex;
    uint per = (u_blocks + uint(ORDER_SCAN_GROUP) - 1u) / uint(ORDER_SCAN_GROUP);
    uint first = min(t * per, u_blocks), last = min(first + per, u_blocks);
    uint total = 0u;
    for (uint b = first; b < last; ++b) total += blocks[b];
    sums[t] = total;
    barrier();
    if (t == 0u) {
        uint run = 0u;
        for (uint k = 0u; k < uint(ORDER_SCAN_GROUP); ++k) {
            uint v = sums[k];
            sums[k] = run;
            run += v;
        }
        command[1] = run;                                           // instances to draw
        uvec3 prepass = split_groups((run + uint(PREPASS_GROUP) - 1u) / uint(PREPASS_GROUP),
                                     u_group_limit);                  // pre-pass groups
        command[4] = prepass.x;
        command[5] = prepass.y;
        command[6] = prepass.z;
    }
    barrier();
    uint run = sums[t];
    for (uint b = first; b < last; ++b) {
        uint v = blocks[b];
        blocks[b] = run;
        run += v;
    }
}
