// A 1-D dispatch of any number of work groups (splatgl/gl/dispatch.py): a direct one runs as
// several dispatches of at most the driver's group count, each with its first group in
// u_group_offset; an indirect one whose plan wrote split_groups() runs x by y groups.  Either
// way linear_group() is the group's index in the 1-D dispatch; the 2-D tail (groups past the
// 1-D count) must be bounds-checked by the shader.  Include it after the local_size layout.
// Twin: splatgl/gl/dispatch.py grid().
uniform uint u_group_offset;

uint linear_group() {
    return u_group_offset + gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x;
}

uint linear_invocation() {
    return linear_group() * gl_WorkGroupSize.x + gl_LocalInvocationID.x;
}

// Indirect dispatch sizes (x, y, z) covering `groups` groups with neither x nor y above `limit`
// (the plan's u_group_limit).
uvec3 split_groups(uint groups, uint limit) {
    uint g = max(groups, 1u);
    uint y = (g + limit - 1u) / limit;
    return uvec3(groups == 0u ? 0u : (g + y - 1u) / y, y, 1u);
}
