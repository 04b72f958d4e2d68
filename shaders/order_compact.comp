// Device-resident order, step 3 of 3 (splatgl/renderers/quad_device.py): the kept splats'
// staged keys and their indices, written in index order at their group's first slot
// (order_scan.comp) plus their rank among the group's kept ones (a scan in shared memory), into
// the radix sorter's keys and values: a stable sort then gives the CPU order, ties by index.
// Slots from u_rows on are seam copies (order_cull.comp's CULL_SEAM): their value is the
// splat's index with WRAP_FLAG (splatgl/cameras/equirect.py; 0x80000000), after every plain one.
// Twin: splatgl/order/cull.py cull_visible(); splatgl/order/chunks.py keys_pairs().

layout(local_size_x = ORDER_GROUP) in;
#include "lib/dispatch.glsl"
layout(std430, binding = ORDER_BINDING_STAGED) readonly buffer Staged { uint staged[]; };
layout(std430, binding = ORDER_BINDING_BLOCKS) readonly buffer Blocks { uint blocks[]; };
layout(std430, binding = ORDER_BINDING_KEYS) writeonly buffer Keys { uint keys[]; };
layout(std430, binding = ORDER_BINDING_VALUES) writeonly buffer Values { uint values[]; };

uniform uint u_count;     // slots staged
uniform uint u_rows;      // splats: slots from here on are seam copies

shared uint ranks[ORDER_GROUP];

void main() {
    uint t = gl_LocalInvocationIndex;
    uint i = linear_invocation();
    uint key = i < u_count ? staged[i] : 0xFFFFFFFFu;
    uint kept = key != 0xFFFFFFFFu ? 1u : 0u;
    ranks[t] = kept;
    barrier();
    for (uint d = 1u; d < uint(ORDER_GROUP); d <<= 1) {   // inclusive scan (Hillis-Steele)
        uint v = t >= d ? ranks[t - d] : 0u;
        barrier();
        ranks[t] += v;
        barrier();
    }
    if (kept != 0u) {
        uint slot = blocks[linear_group()] + ranks[t] - 1u;
        keys[slot] = key;
        values[slot] = i < u_rows ? i : (i - u_rows) | 0x80000000u;
    }
}
