// Tile renderer, stage 6 "rasterize": one 16 x 16 work group per tile, one invocation per pixel
// (3DGS renderCUDA).  Twin: splatgl/reference/rasterize.py rasterize().
// The tile's sorted splats are fetched into shared memory in batches of 256 (one per
// invocation) and blended front to back (DESIGN.md 1-2):
//   power = -0.5 (a dx^2 + c dy^2) - b dx dy,  d = pixel centre - mean2d
//   alpha = min(0.99, o exp(power)), skipped when power > 0 or alpha < 1/255
//   stop, without adding the splat, once T (1 - alpha) < 1e-4
//   C = sum c alpha T,  D = sum z alpha T,  A = 1 - T;  output (C + T bg, A) and D.
#include "lib/tile_common.glsl"

layout(local_size_x = TILE_SIZE, local_size_y = TILE_SIZE) in;

const uint TILE_PIXELS = uint(TILE_SIZE * TILE_SIZE);

layout(std430, binding = TILE_BINDING_OUT_RGBA) writeonly buffer OutRGBA { vec4 out_rgba[]; };
layout(std430, binding = TILE_BINDING_OUT_DEPTH) writeonly buffer OutDepth { float out_depth[]; };

uniform uvec2 u_grid;        // (tiles_x, tiles_y)
uniform uvec2 u_size;        // (width, height) in pixels
uniform vec3 u_background;   // composited as C + T_final bg
uniform uint u_index_mask;   // low bits of a packed key holding the splat index

shared vec4 s_mean_depth[TILE_PIXELS];
shared vec4 s_conic_o[TILE_PIXELS];
shared vec4 s_color[TILE_PIXELS];
shared uint s_done[2];       // invocations finished, per batch parity

void main() {
    uint tile = gl_WorkGroupID.y * u_grid.x + gl_WorkGroupID.x;
    uvec2 pix = gl_GlobalInvocationID.xy;       // (column, row), row 0 = top of the image
    uint rank = gl_LocalInvocationIndex;
    bool inside = pix.x < u_size.x && pix.y < u_size.y;
    vec2 centre = vec2(pix) + 0.5;               // pixel centre (j + 0.5, i + 0.5)
    uvec2 range = tile_ranges[tile];

    bool done = !inside;
    float T = 1.0;
    vec3 C = vec3(0.0);
    float D = 0.0;
    if (rank == 0u) s_done[0] = 0u;
    uint parity = 0u;
    for (uint base = range.x; base < range.y; base += TILE_PIXELS) {
        // Everyone has finished with the previous batch (and read its done count).
        memoryBarrierShared();
        barrier();
        if (done) atomicAdd(s_done[parity], 1u);
        if (rank == 0u) s_done[parity ^ 1u] = 0u;
        uint k = base + rank;
        if (k < range.y) {
#ifdef KEY_PACKED
            uint idx = sort_keys[k].x & u_index_mask;
#else
            uint idx = sort_values[k];
#endif
            s_mean_depth[rank] = proj_mean_depth[idx];
            s_conic_o[rank] = proj_conic_o[idx];
            s_color[rank] = proj_color[idx];
        }
        memoryBarrierShared();
        barrier();
        if (s_done[parity] == TILE_PIXELS) break;   // the same value in every invocation
        parity ^= 1u;
        uint count = min(TILE_PIXELS, range.y - base);
        for (uint j = 0u; !done && j < count; ++j) {
            vec4 q = s_conic_o[j];
            vec4 md = s_mean_depth[j];
            vec2 d = centre - md.xy;
            // power = -0.5 (a dx^2 + c dy^2) - b dx dy, grouped as the NumPy twin groups it.
            float power = -0.5 * (q.x * d.x * d.x + q.z * d.y * d.y) - q.y * d.x * d.y;
            if (power > 0.0) continue;
            float alpha = min(ALPHA_MAX, q.w * exp(power));
            if (alpha < ALPHA_MIN) continue;
            float test_t = T * (1.0 - alpha);
            if (test_t < T_MIN) { done = true; break; }
            float w = alpha * T;                  // alpha_k T_k
            C += s_color[j].rgb * w;
            D += md.z * w;
            T = test_t;
        }
    }
    if (inside) {
        uint o = pix.y * u_size.x + pix.x;
        out_rgba[o] = vec4(C + T * u_background, 1.0 - T);
        out_depth[o] = D;
    }
}
