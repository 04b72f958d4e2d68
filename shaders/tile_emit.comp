// Tile renderer, stage 3 "emit_keys": one invocation per splat (3DGS duplicateWithKeys).
// Twin: splatgl/reference/binning.py emit_keys().  Splat i writes one key per tile of its
// rectangle, rows top to bottom and each row left to right, starting at tile_offsets[i]; the
// key orders by tile_id = y * tiles_x + x, then by the float bits of view z (lib/tile_common).
#include "lib/tile_common.glsl"

layout(local_size_x = SPLAT_GROUP) in;

uniform uint u_count;   // number of splats N
uniform uvec2 u_grid;   // (tiles_x, tiles_y)

void main() {
    uint i = splat_invocation();
    if (i >= u_count || tiles_touched[i] == 0u) return;
    uint k = tile_offsets[i];
    uvec4 rect = proj_rect[i];
    uint depth_bits = floatBitsToUint(proj_mean_depth[i].z);  // z > near > 0: sign bit clear
    for (uint y = rect.y; y < rect.w; ++y) {
        for (uint x = rect.x; x < rect.z; ++x) {
            sort_keys[k] = tile_key(y * u_grid.x + x, depth_bits, i);
#ifndef KEY_PACKED
            sort_values[k] = i;
#endif
            ++k;
        }
    }
}
