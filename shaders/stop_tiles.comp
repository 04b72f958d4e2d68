// Early termination, tile reduction: stopped[t] = 1 when every pixel of 16 x 16 tile t that
// lies in the viewport has T = 1 - A < T_MIN (the mark pass's test), else 0.  One invocation
// per tile, scanning its pixels and leaving at the first open one (most open tiles leave at
// once; a work group per tile with a shared-memory reduction measured 3x slower on llvmpipe).
// Twin: splatgl/early_stop.py stop_tiles.
layout(local_size_x = 64) in;
layout(binding = 0) uniform sampler2D u_accum;
layout(std430, binding = 8) writeonly buffer StopTiles { uint stopped[]; };
uniform ivec2 u_size;    // viewport in pixels
uniform ivec2 u_tiles;   // tile grid (columns, rows)

void main() {
    int t = int(gl_GlobalInvocationID.x);
    if (t >= u_tiles.x * u_tiles.y) return;
    ivec2 lo = ivec2(t % u_tiles.x, t / u_tiles.x) * TILE_SIZE;
    ivec2 hi = min(lo + TILE_SIZE, u_size);
    uint all_stopped = 1u;
    for (int y = lo.y; y < hi.y && all_stopped == 1u; ++y)
        for (int x = lo.x; x < hi.x; ++x)
            if (!(1.0 - texelFetch(u_accum, ivec2(x, y), 0).a < T_MIN)) { all_stopped = 0u; break; }
    stopped[t] = all_stopped;
}
