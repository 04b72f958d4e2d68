// The reference's tile rectangle of a 3DGS splat (3DGS getRect, DESIGN.md 2): on
// p = mean2d - 0.5 (pixel-index coordinates) with radius r = ceil(3 sqrt(lambda_max)) pixels,
// min = clamp(int((p - r) / 16), 0, grid), max = clamp(int((p + r + 15) / 16), 0, grid),
// truncation toward zero (clamped as floats so huge values cannot overflow int); [min, max)
// in tile units.  The tile renderer bins with it; the quad path's ordered pass drops the
// fragments outside it, so its median depth, count and top contributor see the reference's
// splats (lib/ordered_layers.glsl).
// Twin: splatgl/reference/stages.py inria_rect().

uvec4 inria_tile_rect(vec2 mean2d, float r, vec2 grid) {
    vec2 pp = mean2d - 0.5;
    uvec2 rmin = uvec2(clamp(trunc((pp - r) / float(TILE_SIZE)), vec2(0.0), grid));
    uvec2 rmax = uvec2(clamp(trunc((pp + r + float(TILE_SIZE - 1)) / float(TILE_SIZE)), vec2(0.0), grid));
    return uvec4(rmin, rmax);
}
