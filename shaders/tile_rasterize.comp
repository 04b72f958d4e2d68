// Tile renderer, stage 6 "rasterize": one 16 x 16 work group per tile, one invocation per pixel
// (3DGS renderCUDA).
// Twin: splatgl/reference/rasterize.py rasterize().
// The tile's sorted splats are fetched into shared memory in batches of 256 (one per
// invocation) and blended front to back (DESIGN.md 1-2):
//   power = -0.5 (a dx^2 + c dy^2) - b dx dy,  d = pixel centre - mean2d
//   alpha = min(0.99, o exp(power)), skipped when power > 0 or alpha < 1/255
//   stop, without adding the splat, once T (1 - alpha) < 1e-4
//   C = sum c alpha T,  D = sum z alpha T,  A = 1 - T;  output (C + T bg, A) and D.
// Speed-up that cannot change the result: a splat with alpha < 1/255 at every pixel centre of
// the tile (o exp(-q_min / 2) < 1/255, q_min from conic_min_over_box, with a safety margin) is
// dropped from the batch before blending, keeping the order of the others; and a pixel skips
// exp() where power is below that splat's cut-off by the same margin.
// DEVICE_SORT (--sort gpu): the splat indices come from tile_order and the passes from the
// device (ts_passes; each pass an indirect dispatch of whole bands, rows past the grid idle).
// A frame whose keys overflowed the key buffers (ts_overflow; nothing was emitted) writes
// alpha TILE_OVERFLOW_ALPHA, never a drawn alpha, into every pixel: the image read back is the
// renderer's only status (splatgl/renderers/tile_device.py DeviceOrder.overflowed).
// Long lists run in passes (u_pass of u_passes, each over at most TILE_LIST_CHUNK entries of every
// tile's list), carrying (C, +-T) in out_rgba and D in out_depth between passes (T negated once
// the pixel stopped): llvmpipe ends every loop of an invocation after 65535 iterations in all,
// and one pass stays well below that, so a tile of 50k splats is not cut short.
// SURFEL (2DGS, twin: reference/rasterize.py's surfel branch, splatgl/splatmath/surfel.py surfel_alpha):
// every splat of the tile's list is kept (its tile rectangle is already the box_rect of its
// pixel box) and a pixel evaluates the ray-splat intersection instead of the conic:
//   h_u = T'_0 - dx T_2, h_v = T'_1 - dy T_2, (u, v, 1) ~ h_u x h_v (2DGS eq. 9-10),
//   rho = min(u^2 + v^2, F |d|^2) (low pass, eq. 11, F = SURFEL_FILTER_INV_SQUARE),
//   alpha = min(0.99, o exp(-rho / 2)), skipped below 1/255; same early stop; D sums the
//   view z of the hit (depth_row . (u, v, 1)) where rho_3d <= rho_2d, else the centre's z.
// Further layers (splatgl/output/layers.py; twin: splatgl/reference/layers.py BatchLayers),
// each behind its own switch and carried between passes like C and D:
//   NORMAL_OUTPUT: N = sum n w with the splat's camera-space normal (proj_normal);
//   ORDERED_OUTPUT: median z = the z of the last splat blended while T > MEDIAN_T (T before
//     it), top = the first splat of the largest w = alpha T (its index + 1; 0: none), count;
//   UNDER: a splat whose z is at or behind the pixel's geometry depth (under_depth, the
//     splats' metric, +inf: none) is skipped like one below 1/255.
// PER_PIXEL (the per-pixel order, twin: splatgl/reference/per_pixel.py window_order and
// _raster_batch with a window): a pixel holds back up to ORDER_WINDOW contributions sorted by
// the depth of each splat's peak along its ray (lib/peak_depth.glsl; surfels: the hit's view z);
// each new one joins them and, when that makes ORDER_WINDOW + 1, the nearest is blended (ties:
// the earlier in the list).  The rest are blended in order at the end of each pass.  D sums
// that depth.
#ifdef DEVICE_SORT
#define TILE_STATE 1
#define TILE_ORDER 1
#define TILE_NO_KEYS 1
#endif
#include "lib/tile_common.glsl"
#ifdef SURFEL
#include "lib/camera.glsl"
#include "lib/surfel.glsl"
#endif
#if defined(PER_PIXEL) && !defined(SURFEL)
#include "lib/peak_depth.glsl"
#endif

layout(local_size_x = TILE_SIZE, local_size_y = TILE_SIZE) in;

const uint TILE_PIXELS = uint(TILE_SIZE * TILE_SIZE);
// Safety margin on q = -2 power for the two skips above: relative and absolute (q is ~1..100;
// float rounding of q and exp is ~1e-6 relative, so these margins are never reached by it).
const float Q_MARGIN_REL = 1.0e-3;
const float Q_MARGIN_ABS = 1.0e-2;

layout(std430, binding = TILE_BINDING_OUT_RGBA) buffer OutRGBA { vec4 out_rgba[]; };
layout(std430, binding = TILE_BINDING_OUT_DEPTH) buffer OutDepth { float out_depth[]; };

uniform uvec2 u_grid;        // (tiles_x, tiles_y)
uniform uvec2 u_size;        // (width, height) in pixels
uniform vec3 u_background;   // composited as C + T_final bg
uniform uint u_index_mask;   // low bits of a packed key holding the splat index
uniform uint u_tile_row0;    // first tile row of this dispatch (the image is drawn in bands)
uniform uint u_pass;         // this pass (0-based) over the tiles' lists ...
uniform uint u_passes;       // ... of this many, each over TILE_LIST_CHUNK entries per tile
#ifdef NORMAL_OUTPUT
layout(std430, binding = TILE_BINDING_OUT_NORMAL) buffer OutNormal { vec4 out_normal[]; };
shared vec4 s_normal[TILE_PIXELS];     // (n, 0) of the kept splats
#endif
#ifdef ORDERED_OUTPUT
// (median z, top weight) and (count, top index + 1) per pixel.
layout(std430, binding = TILE_BINDING_OUT_ORDERED_F) buffer OutOrderedF { vec2 out_ordered_f[]; };
layout(std430, binding = TILE_BINDING_OUT_ORDERED_U) buffer OutOrderedU { uvec2 out_ordered_u[]; };
shared uint s_index[TILE_PIXELS];      // splat index of the kept splats
#endif
#ifdef UNDER
layout(std430, binding = TILE_BINDING_UNDER) readonly buffer UnderDepth { float under_depth[]; };
#endif
#if defined(PER_PIXEL) && !defined(SURFEL)
uniform vec4 u_rays;         // (cx, cy, fx, fy): ray coordinates a = (x - cx, y - cy) / (fx, fy)
shared vec4 s_peak0[TILE_PIXELS];      // peak_depth coefficients (s_color.w holds Q2_yy,
shared vec4 s_peak1[TILE_PIXELS];      // s_mean_cut.w, the 3DGS view z, is not read: r_z)
#endif

shared vec4 s_mean_cut[TILE_PIXELS];   // (u, v, power cut-off, view z) of the kept splats
shared vec4 s_conic_o[TILE_PIXELS];    // (a, b, c, opacity)
shared vec4 s_color[TILE_PIXELS];      // (r, g, b, 0)
#ifdef SURFEL
shared vec2 s_depth_uv[TILE_PIXELS];   // (a_u.z, a_v.z) of depth_row (SURFEL: mean_cut is
                                       // (c, z, o), conic_o the centred rows T'_0.xy, T'_1.xy)
#endif
shared uint s_slot[TILE_PIXELS];       // keep flag, then (after the scan) the kept slot
shared uint s_alive[TILE_PIXELS];      // 1 while the invocation's pixel still blends
shared uint s_kept;                    // splats kept in this batch
shared uint s_alive_count;             // invocations still blending

#ifdef PER_PIXEL
// This invocation's window: w_n entries sorted by depth w_t, colour and alpha in w_c.
float w_t[ORDER_WINDOW];
vec4 w_c[ORDER_WINDOW];
int w_n = 0;

// Front-to-back blend of one contribution with the early stop (as the global order's loop).
void blend_one(float z, vec4 c, inout vec3 C, inout float D, inout float T, inout bool done) {
    float test_t = T * (1.0 - c.a);
    if (test_t < T_MIN) { done = true; return; }
    float w = c.a * T;                    // alpha_k T_k
    C += c.rgb * w;
    D += z * w;
    T = test_t;
}

// Insert into the sorted window (w_n < ORDER_WINDOW), after entries of equal depth.  Loops of
// constant trip count without early exits and constant indices only, so the compiler unrolls
// them into selects (llvmpipe's per-lane dynamic array indexing is slow, and it counts loop
// iterations).
void window_insert(float z, vec4 c) {
    int p = 0;                            // entries at or before z: the new entry's slot
    for (int i = 0; i < ORDER_WINDOW; ++i) p += (i < w_n && w_t[i] <= z) ? 1 : 0;
    for (int i = ORDER_WINDOW - 1; i > 0; --i) {
        if (i > p && i <= w_n) { w_t[i] = w_t[i - 1]; w_c[i] = w_c[i - 1]; }
    }
    for (int i = 0; i < ORDER_WINDOW; ++i) {
        if (i == p) { w_t[i] = z; w_c[i] = c; }
    }
    w_n += 1;
}

void window_push(float z, vec4 c, inout vec3 C, inout float D, inout float T, inout bool done) {
    if (w_n < ORDER_WINDOW) { window_insert(z, c); return; }
    if (z < w_t[0]) { blend_one(z, c, C, D, T, done); return; }
    blend_one(w_t[0], w_c[0], C, D, T, done);
    for (int i = 0; i < ORDER_WINDOW - 1; ++i) { w_t[i] = w_t[i + 1]; w_c[i] = w_c[i + 1]; }
    w_n -= 1;
    window_insert(z, c);
}

void window_flush(inout vec3 C, inout float D, inout float T, inout bool done) {
    for (int i = 0; i < ORDER_WINDOW; ++i) {
        if (i < w_n && !done) blend_one(w_t[i], w_c[i], C, D, T, done);
    }
    w_n = 0;
}
#endif

void main() {
    uvec2 group = gl_WorkGroupID.xy + uvec2(0u, u_tile_row0);   // this tile's (x, y) in the grid
#ifdef DEVICE_SORT
    if (group.y >= u_grid.y) return;             // a whole band past the last row (indirect)
    uint passes = ts_passes;                     // from the device (tile_ranges.comp)
#else
    uint passes = u_passes;
#endif
    uint tile = group.y * u_grid.x + group.x;
    uvec2 pix = group * uint(TILE_SIZE) + gl_LocalInvocationID.xy;  // (column, row), row 0 = top
    uint rank = gl_LocalInvocationIndex;
    bool inside = pix.x < u_size.x && pix.y < u_size.y;
    vec2 centre = vec2(pix) + 0.5;               // pixel centre (j + 0.5, i + 0.5)
    // Box of this tile's pixel centres inside the image.
    vec2 box_lo = vec2(group * uint(TILE_SIZE)) + 0.5;
    vec2 box_hi = min(box_lo + float(TILE_SIZE - 1), vec2(u_size) - 0.5);
    uvec2 range = tile_ranges[tile];
    uint first = range.x + min(range.y - range.x, u_pass * uint(TILE_LIST_CHUNK));
    range = uvec2(first, min(range.y, first + uint(TILE_LIST_CHUNK)));
    uint o = inside ? pix.y * u_size.x + pix.x : 0u;

    bool done = !inside;
    float T = 1.0;
    vec3 C = vec3(0.0);
    float D = 0.0;
#ifdef NORMAL_OUTPUT
    vec3 N = vec3(0.0);
#endif
#ifdef ORDERED_OUTPUT
    vec2 median_top = vec2(0.0);                 // (median z, top weight)
    uvec2 count_top = uvec2(0u);                 // (count, top index + 1)
#endif
#ifdef UNDER
    float geometry = inside ? under_depth[o] : 0.0;
#endif
    if (u_pass > 0u && inside) {                 // resume the previous pass's state
        vec4 state = out_rgba[o];
        C = state.rgb;
        T = abs(state.w);
        done = state.w < 0.0;
        D = out_depth[o];
#ifdef NORMAL_OUTPUT
        N = out_normal[o].xyz;
#endif
#ifdef ORDERED_OUTPUT
        median_top = out_ordered_f[o];
        count_top = out_ordered_u[o];
#endif
    }
    for (uint base = range.x; base < range.y; base += TILE_PIXELS) {
        memoryBarrierShared();
        barrier();                                // the previous batch is consumed
        // Fetch one splat per invocation and decide whether it can reach the tile:
        // alpha >= 1/255 needs q <= 2 ln(255 o).
        uint k = base + rank;
        bool keep = false;
        vec4 mc = vec4(0.0), qo = vec4(0.0);
#ifdef SURFEL
        vec2 duv = vec2(0.0);
#endif
#ifdef NORMAL_OUTPUT
        vec4 nrm = vec4(0.0);
#endif
#ifdef ORDERED_OUTPUT
        uint sidx = 0u;
#endif
#if defined(PER_PIXEL) && !defined(SURFEL)
        vec4 pk0 = vec4(0.0), pk1 = vec4(0.0);
#endif
        if (k < range.y) {
#if defined(DEVICE_SORT)
            uint idx = tile_order[k];
#elif defined(KEY_PACKED)
            uint idx = sort_keys[k].x & u_index_mask;
#else
            uint idx = sort_values[k];
#endif
#ifdef NORMAL_OUTPUT
            nrm = proj_normal[idx];
#endif
#ifdef ORDERED_OUTPUT
            sidx = idx;
#endif
#ifdef SURFEL
            keep = true;
            mc = proj_mean_depth[idx];
            qo = proj_conic_o[idx];
            duv = proj_surfel[idx].xy;
            s_color[rank] = proj_color[idx];
#else
            vec4 md = proj_mean_depth[idx];
            qo = proj_conic_o[idx];
            float q_cut = 2.0 * log(qo.w / ALPHA_MIN) * (1.0 + Q_MARGIN_REL) + Q_MARGIN_ABS;
            keep = conic_min_over_box(qo.xyz, md.xy, box_lo, box_hi) <= q_cut;
            mc = vec4(md.xy, -0.5 * q_cut, md.z);
            if (keep) s_color[rank] = proj_color[idx];
#ifdef PER_PIXEL
            if (keep) {
                pk0 = proj_peak[3u * idx];
                pk1 = proj_peak[3u * idx + 1u];
                vec4 pk2 = proj_peak[3u * idx + 2u];
                s_color[rank].w = pk2.x;
                mc.w = pk2.y;                     // r_z (z is the peak depth in this mode)
            }
#endif
#endif
        }
        s_slot[rank] = keep ? 1u : 0u;
        s_alive[rank] = done ? 0u : 1u;
        memoryBarrierShared();
        barrier();
        if (rank == 0u) {                         // order-preserving compaction (serial scan)
            uint kept = 0u, alive = 0u;
            for (uint j = 0u; j < TILE_PIXELS; ++j) {
                uint flag = s_slot[j];
                s_slot[j] = kept;
                kept += flag;
                alive += s_alive[j];
            }
            s_kept = kept;
            s_alive_count = alive;
        }
        memoryBarrierShared();
        barrier();
        if (s_alive_count == 0u) break;           // the same value in every invocation
        vec4 color = s_color[rank];               // (rgb, 0; PER_PIXEL: the third peak value)
        memoryBarrierShared();
        barrier();                                // colours read before slots are overwritten
        if (keep) {
            uint slot = s_slot[rank];
            s_mean_cut[slot] = mc;
            s_conic_o[slot] = qo;
            s_color[slot] = color;
#ifdef SURFEL
            s_depth_uv[slot] = duv;
#endif
#ifdef NORMAL_OUTPUT
            s_normal[slot] = nrm;
#endif
#ifdef ORDERED_OUTPUT
            s_index[slot] = sidx;
#endif
#if defined(PER_PIXEL) && !defined(SURFEL)
            s_peak0[slot] = pk0;
            s_peak1[slot] = pk1;
#endif
        }
        memoryBarrierShared();
        barrier();
        uint count = s_kept;
        for (uint j = 0u; !done && j < count; ++j) {
            vec4 q = s_conic_o[j];
            vec4 m = s_mean_cut[j];
#ifdef SURFEL
            vec3 depth_row = vec3(s_depth_uv[j], m.z);   // z of (u, v, 1)
#ifdef ORTHOGRAPHIC
            vec3 t2 = vec3(0.0, 0.0, 1.0);
#else
            vec3 t2 = depth_row;                         // T_2 = (a_u.z, a_v.z, p.z)
#endif
            float z;
            float alpha = surfel_alpha(vec3(q.xy, 0.0), vec3(q.zw, 0.0), t2, depth_row, m.w,
                                       centre - m.xy, z);
            if (alpha < ALPHA_MIN) continue;
#else
            float z = m.w;
            vec2 d = centre - m.xy;
            // power = -0.5 (a dx^2 + c dy^2) - b dx dy, grouped as the NumPy twin groups it.
            float power = -0.5 * (q.x * d.x * d.x + q.z * d.y * d.y) - q.y * d.x * d.y;
            if (power > 0.0 || power < m.z) continue;
            float alpha = min(ALPHA_MAX, q.w * exp(power));
            if (alpha < ALPHA_MIN) continue;
#endif
#ifdef UNDER
            if (z >= geometry) continue;          // behind the geometry: not blended
#endif
#ifdef PER_PIXEL
#ifndef SURFEL
            z = peak_depth(s_peak0[j], s_peak1[j], vec2(s_color[j].w, m.w), (centre - u_rays.xy) / u_rays.zw);
#endif
            window_push(z, vec4(s_color[j].rgb, alpha), C, D, T, done);
            continue;
#endif
            float test_t = T * (1.0 - alpha);
            if (test_t < T_MIN) { done = true; break; }
            float w = alpha * T;                  // alpha_k T_k
            C += s_color[j].rgb * w;
            D += z * w;
#ifdef NORMAL_OUTPUT
            N += s_normal[j].xyz * w;
#endif
#ifdef ORDERED_OUTPUT
            if (T > MEDIAN_T) median_top.x = z;   // T before this splat
            if (w > median_top.y) {               // the first of equal weights stays
                median_top.y = w;
                count_top.y = s_index[j] + 1u;
            }
            count_top.x += 1u;
#endif
            T = test_t;
        }
    }
#ifdef PER_PIXEL
    window_flush(C, D, T, done);                 // the window restarts with every pass
#endif
    if (inside) {
        bool last = u_pass + 1u == passes;
        out_rgba[o] = last ? vec4(C + T * u_background, 1.0 - T) : vec4(C, done ? -T : T);
#ifdef DEVICE_SORT
        if (last && ts_overflow != 0u) out_rgba[o].w = TILE_OVERFLOW_ALPHA;   // draw again
#endif
        out_depth[o] = D;
#ifdef NORMAL_OUTPUT
        out_normal[o] = vec4(N, 0.0);
#endif
#ifdef ORDERED_OUTPUT
        out_ordered_f[o] = median_top;
        out_ordered_u[o] = count_top;
#endif
    }
}
