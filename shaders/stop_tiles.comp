// Early termination, stop-mask reduction: for each 16 x 16 tile t, stopped[t] holds one bit per
// STOP_BLOCK_SIZE-square block of the tile (bit 4 by + bx for block column bx, row by), set when
// every pixel of that block inside the viewport has T = 1 - A < T_MIN (the mark pass's test);
// a tile is wholly stopped when all 16 bits are set.  One invocation per tile, scanning each
// block until its first open pixel (open blocks mostly leave at once; a work group per tile
// with a shared-memory reduction measured 3x slower on llvmpipe).
// Twin: splatgl/splatmath/early_stop.py stop_tiles(), stop_blocks().
layout(local_size_x = STOP_TILES_GROUP) in;
layout(binding = ACCUM_UNIT) uniform sampler2D u_accum;
layout(std430, binding = BINDING_STOP_TILES) writeonly buffer StopTiles { uint stopped[]; };
uniform ivec2 u_size;    // viewport in pixels
uniform ivec2 u_tiles;   // tile grid (columns, rows)

const int BLOCKS = TILE_SIZE / STOP_BLOCK_SIZE;   // blocks per tile side (4: 16 bits)

void main() {
    int t = int(gl_GlobalInvocationID.x);
    if (t >= u_tiles.x * u_tiles.y) return;
    ivec2 tile = ivec2(t % u_tiles.x, t / u_tiles.x) * TILE_SIZE;
    uint bits = 0u;
    for (int b = 0; b < BLOCKS * BLOCKS; ++b) {
        ivec2 lo = tile + ivec2(b % BLOCKS, b / BLOCKS) * STOP_BLOCK_SIZE;
        ivec2 hi = min(lo + STOP_BLOCK_SIZE, u_size);
        bool block_stopped = true;
        for (int y = lo.y; y < hi.y && block_stopped; ++y)
            for (int x = lo.x; x < hi.x; ++x)
                if (!(1.0 - texelFetch(u_accum, ivec2(x, y), 0).a < T_MIN)) {
                    block_stopped = false;
                    break;
                }
        if (block_stopped) bits |= 1u << uint(b);
    }
    stopped[t] = bits;
}
