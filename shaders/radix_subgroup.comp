// The radix sort's probe, one work group run once per sorter: the device's subgroup size, which the
// downsweep's subgroup paths are compiled with (RADIX_WARP).  Writes it where the state
// block's first word (st_or) goes; the sorter initialises the state after it.
// Twin: none (plumbing: a probe of the device's subgroup size).
#if defined(RADIX_MATCH_KHR)
#extension GL_KHR_shader_subgroup_basic : require
#define SUBGROUP_SIZE gl_SubgroupSize
#else
#extension GL_ARB_shader_ballot : require
#define SUBGROUP_SIZE gl_SubGroupSizeARB
#endif

layout(local_size_x = RADIX_GROUP) in;  // the downsweep's group, as it will run
layout(std430, binding = RADIX_BINDING_STATE) writeonly buffer Probe { uint probe_size; };

void main() {
    if (gl_LocalInvocationID.x == 0u) probe_size = uint(SUBGROUP_SIZE);
}
