// Per-view buffers of the tile renderer (splatgl/renderers/tile.py allocates and binds them at
// the TILE_BINDING_* points of splatgl/gl/bindings.py).
// Twin arrays: splatgl/reference/stages.py ProjectedSplats and reference/binning.py.
// Twin: splatgl/reference/binning.py emit_keys(), depth_bits();
//   splatgl/renderers/tile_keys.py KeyLayout.to_reference().
//
// proj_mean_depth[i] = (u, v, view z, 0): image position in pixels (centre of pixel (i, j) at
//                      (j + 0.5, i + 0.5)) and camera-space depth in world units.
// proj_conic_o[i]    = (a, b, c, opacity): Q = Sigma'^-1 = [[a, b], [b, c]] in 1/px^2.
// proj_color[i]      = (r, g, b, 0): SH colour, clamped below at 0.
// proj_rect[i]       = (min x, min y, max x, max y): tile rectangle [min, max), tile units.
// tiles_touched[i]   = (max x - min x) (max y - min y), 0 for a culled splat.
// tile_offsets[i]    = exclusive prefix sum of tiles_touched: where splat i's keys start.
// sort_keys[k]       = 64-bit key as (low word, high word); see tile_key() below.
// sort_values[k]     = splat index of key k (only when the index is not packed in the key).
// tile_ranges[t]     = [start, end) of tile t's run in the sorted keys.
layout(std430, binding = TILE_BINDING_MEAN_DEPTH) buffer ProjMeanDepth { vec4 proj_mean_depth[]; };
layout(std430, binding = TILE_BINDING_CONIC_O) buffer ProjConicO { vec4 proj_conic_o[]; };
layout(std430, binding = TILE_BINDING_COLOR) buffer ProjColor { vec4 proj_color[]; };
layout(std430, binding = TILE_BINDING_RECT) buffer ProjRect { uvec4 proj_rect[]; };
layout(std430, binding = TILE_BINDING_TOUCHED) buffer TilesTouched { uint tiles_touched[]; };
layout(std430, binding = TILE_BINDING_OFFSETS) buffer TileOffsets { uint tile_offsets[]; };
#ifndef TILE_NO_KEYS  // (a compute shader may have 16 storage blocks on llvmpipe)
layout(std430, binding = TILE_BINDING_KEYS) buffer SortKeys { uvec2 sort_keys[]; };
layout(std430, binding = TILE_BINDING_VALUES) buffer SortValues { uint sort_values[]; };
#endif
layout(std430, binding = TILE_BINDING_RANGES) buffer TileRanges { uvec2 tile_ranges[]; };
#ifdef PER_PIXEL
// The per-pixel order (twin: splatgl/splatmath/peak.py peak_coefficients): three vec4 per splat
// of lib/peak_depth.glsl's coefficients, written by the project stage (3DGS only).
layout(std430, binding = TILE_BINDING_PEAK) buffer ProjPeak { vec4 proj_peak[]; };
#endif
#ifdef SURFEL
// 2DGS surfels (SURFEL defined) reuse the buffers above with these meanings (twin:
// reference/stages.py project_surfels, rows of splatgl/splatmath/surfel.py SurfelScreen):
//   proj_mean_depth[i] = (c_x, c_y, view z, opacity): projected centre c (the low-pass centre),
//                        the centre's camera z (sort key; depth_row.z) and o.
//   proj_conic_o[i]    = (T'_00, T'_01, T'_10, T'_11): centred rows T'_r = T_r - c_r T_2 of
//                        T = P H (2DGS eq. 5); their third entries are 0 exactly.
//   proj_color[i]      = (r, g, b, 0) as for 3DGS.
//   proj_surfel[i]     = (a_u.z, a_v.z, 0, 0): with view z, depth_row = (a_u.z, a_v.z, z), the
//                        camera z of tangent point (u, v, 1); perspective T_2 = depth_row,
//                        orthographic T_2 = (0, 0, 1).
layout(std430, binding = TILE_BINDING_SURFEL) buffer ProjSurfel { vec4 proj_surfel[]; };
#endif
// The device order (--sort gpu, splatgl/renderers/tile_device.py; twin: the CPU order in
// splatgl/renderers/tile.py, _scan, _sort, _ranges), each block declared where a shader asks
// for it (TILE_STATE, TILE_SCAN_BLOCKS, TILE_ORDER, TILE_DEV_KEYS), as llvmpipe allows a compute
// shader 16 storage blocks.  ts_args holds u_emit_slots emit dispatches, then u_raster_slots
// rasterize passes, each (groups x, y, z, 0), 0 groups to skip.
#ifdef TILE_STATE
layout(std430, binding = TILE_BINDING_STATE) coherent buffer TileState {
    uint ts_total;       // keys the splats emit: the scan's end
    uint ts_overflow;    // 1 when ts_total > the key buffers' capacity: nothing emitted
    uint ts_sort_count;  // keys to sort (ts_total, 0 after an overflow): the sorter reads it
    uint ts_max_touched; // the largest tiles_touched
    uint ts_passes;      // rasterize passes: the longest tile list over TILE_LIST_CHUNK
    uint ts_splats;      // splats N: the depth presort's count (tile_ranges.comp stage 4)
    uint ts_pad1, ts_pad2;
    uvec4 ts_key_args;   // groups of SPLAT_GROUP over the keys (0 after an overflow)
    uvec4 ts_args[];
};
#endif
#ifdef TILE_SCAN_BLOCKS
layout(std430, binding = TILE_BINDING_SCAN_BLOCKS) buffer ScanBlocks { uvec2 scan_blocks[]; };
#endif
#ifdef TILE_ORDER
layout(std430, binding = TILE_BINDING_ORDER) buffer TileOrder { uint tile_order[]; };
#endif
#ifdef TILE_SPLAT_ORDER
layout(std430, binding = TILE_BINDING_SPLAT_ORDER) buffer SplatOrder { uint splat_order[]; };
#endif
#ifdef TILE_DEV_KEYS
layout(std430, binding = TILE_BINDING_SORT_KEYS) buffer DevKeys { uint dev_keys[]; };
layout(std430, binding = TILE_BINDING_SORT_VALUES) buffer DevValues { uint dev_values[]; };
#endif

#ifdef TILE_STATE
// Dispatch arguments covering n invocations of groups of SPLAT_GROUP, 2D past u_group_limit groups
// (splatgl/renderers/tile_keys.py splat_groups).
uniform uint u_group_limit;   // splatgl/gl/dispatch.py portable_limit()
uvec4 splat_args(uint n) {
    uint groups = max(1u, (n + uint(SPLAT_GROUP) - 1u) / uint(SPLAT_GROUP));
    uint gy = (groups + u_group_limit - 1u) / u_group_limit;
    return uvec4((groups + gy - 1u) / gy, gy, 1u, 0u);
}
#endif
#ifdef NORMAL_OUTPUT
// proj_normal[i] = (n, 0): the normal layer's camera-space unit normal (lib/normal.glsl).
layout(std430, binding = TILE_BINDING_NORMAL) buffer ProjNormal { vec4 proj_normal[]; };
#endif

// Key layout (DESIGN.md section 2: tile id major, float bits of view z minor, compared as one
// unsigned 64-bit integer).  splatgl packs it as
//   key = (tile << u_tile_shift) | (depth_bits << u_depth_shift) | (KEY_PACKED ? index : 0)
// The reference's own layout is tile_shift = 32, depth_shift = 0.  With KEY_PACKED the splat
// index fills the low u_depth_shift bits (depth bits are 31 wide: view z > 0 has sign bit 0),
// so sorting the keys alone equals the reference's stable sort (ties keep index order).
uniform uint u_tile_shift;
uniform uint u_depth_shift;

// uint64(v) << s as (low word, high word), 0 <= s <= 63 (GLSL 4.3 has no 64-bit integers and
// shifts by 32 or more are undefined, hence the cases).
uvec2 shift_left64(uint v, uint s) {
    if (s == 0u) return uvec2(v, 0u);
    if (s < 32u) return uvec2(v << s, v >> (32u - s));
    return uvec2(0u, v << (s - 32u));
}

uvec2 tile_key(uint tile, uint depth_bits, uint index) {
    uvec2 key = shift_left64(tile, u_tile_shift) | shift_left64(depth_bits, u_depth_shift);
#ifdef KEY_PACKED
    key.x |= index;
#endif
    return key;
}

// Splat index of this invocation in a per-splat dispatch of (groups_x, groups_y) work groups of
// SPLAT_GROUP invocations (2D so that more than 65535 groups' worth of splats fit).
uint splat_invocation() {
    return gl_GlobalInvocationID.y * (gl_NumWorkGroups.x * uint(SPLAT_GROUP)) + gl_GlobalInvocationID.x;
}

// Smallest q(d) = d^T Q d = a dx^2 + 2 b dx dy + c dy^2 (so power = -q / 2) over the points of
// the box [lo, hi] (pixels; d = point - mean), Q = [[a, b], [b, c]] positive definite.  Zero
// when the mean lies in the box; otherwise the minimum of this convex function lies on an
// edge, where it is the 1D minimum dy = -b dx / c (or dx = -b dy / a) clamped to the edge.
float conic_min_over_box(vec3 Q, vec2 mean, vec2 lo, vec2 hi) {
    vec2 d0 = lo - mean, d1 = hi - mean;
    if (d0.x <= 0.0 && d1.x >= 0.0 && d0.y <= 0.0 && d1.y >= 0.0) return 0.0;
    float best = 3.0e38;
    for (int e = 0; e < 2; ++e) {
        float dx = e == 0 ? d0.x : d1.x;          // vertical edges, dy free
        float dy = clamp(-Q.y * dx / Q.z, d0.y, d1.y);
        best = min(best, Q.x * dx * dx + 2.0 * Q.y * dx * dy + Q.z * dy * dy);
        float ey = e == 0 ? d0.y : d1.y;          // horizontal edges, dx free
        float ex = clamp(-Q.y * ey / Q.x, d0.x, d1.x);
        best = min(best, Q.x * ex * ex + 2.0 * Q.y * ex * ey + Q.z * ey * ey);
    }
    return best;
}
