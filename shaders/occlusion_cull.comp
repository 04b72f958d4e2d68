// Early termination, splat-level occlusion cull, tile clipping and order-preserving compaction.
//
// Slots [u_start, u_end) of the sorted order form one draw batch.  A splat survives unless its
// quad's screen rectangle lies only on stopped tiles (stop_tiles.comp; every pixel there has
// T < T_MIN, so the depth test would reject each of its fragments anyway) or off the viewport.
// With u_split, a survivor whose tile rectangle holds stopped tiles is drawn as pieces that
// cover only its open tiles: per tile row, each run of consecutive open tiles is one piece, and
// a row holding a single run equal to the previous row's extends that row's piece downwards.
// Pieces of one splat never overlap, so every pixel still receives each splat at most once.
// A piece is (value, x0 | x1 << 16, y0 | y1 << 16) in tiles (inclusive), or (value, WHOLE, 0)
// for the splat's whole quad; the vertex stage clips the quad to the piece (lib/quad_emit.glsl).
//
// Work group g owns the SEGMENT slots from u_start + g SEGMENT and the PIECE_CAPACITY piece
// places from (u_cmd_base + g) PIECE_CAPACITY.  Each invocation counts its slots' pieces, a
// work-group prefix sum places them in sorted order (deterministic: no atomic append), and the
// draw command (4, pieces, 0, first place, survivors) becomes command u_cmd_base + g, so a
// multi-draw-indirect over the batch's commands draws the pieces front to back (commands run in
// order; the instanced attribute reads pieces[baseInstance + instance]).  A segment whose pieces
// would overflow its places draws its survivors whole instead (same image, more fragments).
// Variants: PREPARED (3DGS after quad_prepass.comp: the value is the slot, read back by
// quad_light.vert), SURFEL (2DGS, the value is the splat index for surfel.vert), neither (3DGS
// vertex path, the splat index for quad.vert).  Twin: splatgl/early_stop.py occlusion_cull and
// tile_pieces.
#include "lib/camera.glsl"
#include "lib/scene.glsl"
#include "lib/project.glsl"
#ifdef SURFEL
#include "lib/surfel.glsl"
#elif !defined(PREPARED)
#include "lib/sh.glsl"
#include "lib/splat_setup.glsl"
#endif

#define GROUP 256
#define PER_INVOCATION 4
layout(local_size_x = GROUP) in;
layout(std430, binding = 5) readonly buffer Order { uint order[]; };
#ifdef PREPARED
layout(std430, binding = 6) readonly buffer Prepared { vec4 prepared[]; };
#endif
layout(std430, binding = 8) readonly buffer StopTiles { uint stopped[]; };
layout(std430, binding = 9) writeonly buffer Pieces { uint pieces[]; };   // 3 uints a piece
// DrawArraysIndirectCommand (count, instanceCount, first, baseInstance) in moderngl's 20-byte
// stride (render_indirect passes stride 20 for arrays too): 5 uints per command, the fifth
// (padding for GL) holds the segment's surviving splats.
layout(std430, binding = 10) writeonly buffer Commands { uint commands[]; };
uniform uint u_start;
uniform uint u_end;
uniform uint u_cmd_base;
uniform ivec2 u_tiles;         // tile grid (columns, rows)
uniform bool u_check_tiles;    // false on the first batch: nothing has stopped yet
uniform bool u_split;          // draw survivors as pieces over their open tiles

shared uint s_scan[GROUP];

// Pixel rectangle [lo, hi] containing the splat's quad, and the value a survivor stores.
// False: the splat draws nothing (culled by its own setup).
bool splat_rect(uint k, out vec2 lo, out vec2 hi, out uint value) {
#ifdef PREPARED
    value = k;
    vec4 d = prepared[4u * k + 3u];
    if (d.z == 0.0) return false;
    vec4 a = prepared[4u * k], b = prepared[4u * k + 1u];
    vec2 half_size = abs(a.zw) + abs(b.xy);   // corners mean +- axis1 +- axis2
    lo = a.xy - half_size;
    hi = a.xy + half_size;
    return true;
#elif defined(SURFEL)
    uint i = order[k];
    value = i;
    vec4 a = splat_a[i];
    vec3 p = u_view_rot * a.xyz + u_view_trans;
    if (p.z <= u_near) return false;
    mat3 rot = quat_to_rotmat(splat_q[i]);
    vec2 s = splat_s[i].xy;
    vec2 center;
    vec3 t0, t1, t2;
    surfel_screen(p, u_view_rot * (rot[0] * s.x), u_view_rot * (rot[1] * s.y), center, t0, t1, t2);
    return surfel_bounds(center, t0, t1, t2, a.w, lo, hi);
#else
    uint i = order[k];
    value = i;
    ScreenSplat s;
    if (!setup_splat(i, s)) return false;
    vec2 half_size = abs(s.axis1) + abs(s.axis2);
    lo = s.mean2d - half_size;
    hi = s.mean2d + half_size;
    return true;
#endif
}

bool is_open(int tx, int ty) { return stopped[ty * u_tiles.x + tx] == 0u; }

// Writes piece p = (x0, x1, y0, y1) of the splat with tile rectangle r = (x0, y0, x1, y1) as
// piece number i (WHOLE when it is all of r).
void put(uint value, ivec4 p, ivec4 r, bool write, uint i) {
    if (!write) return;
    pieces[3u * i] = value;
    bool whole = p == ivec4(r.x, r.z, r.y, r.w);
    pieces[3u * i + 1u] = whole ? WHOLE_PIECE : uint(p.x) | uint(p.y) << 16;
    pieces[3u * i + 2u] = whole ? 0u : uint(p.z) | uint(p.w) << 16;
}

// The pieces over the open tiles of tile rectangle r (see the header); written from piece
// number `at` when `write`.  Returns their count.
uint walk(uint value, ivec4 r, bool write, uint at) {
    uint n = 0u;
    bool pending = false;
    ivec4 p = ivec4(0);   // the piece a later row may extend: (x0, x1, y0, y1)
    for (int ty = r.y; ty <= r.w; ++ty) {
        int runs = 0, ra = 0, rb = 0;
        int tx = r.x;
        while (tx <= r.z) {
            if (!is_open(tx, ty)) { ++tx; continue; }
            int a = tx;
            while (tx <= r.z && is_open(tx, ty)) ++tx;
            ++runs;
            if (runs == 1) { ra = a; rb = tx - 1; continue; }
            if (runs == 2) {   // a row of several runs: each its own piece
                if (pending) { put(value, p, r, write, at + n); ++n; pending = false; }
                put(value, ivec4(ra, rb, ty, ty), r, write, at + n); ++n;
            }
            put(value, ivec4(a, tx - 1, ty, ty), r, write, at + n); ++n;
        }
        if (runs == 1) {
            if (pending && p.x == ra && p.y == rb && p.w == ty - 1) {
                p.w = ty;
            } else {
                if (pending) { put(value, p, r, write, at + n); ++n; }
                pending = true;
                p = ivec4(ra, rb, ty, ty);
            }
        }
    }
    if (pending) { put(value, p, r, write, at + n); ++n; }
    return n;
}

// A quad covers the pixels whose centres (j + 0.5, i + 0.5) lie in it, all inside the pixel
// range [floor(lo), floor(hi)]; it survives unless that range misses the viewport or every tile
// it touches is stopped.  Returns the pieces it is drawn as (0: culled) and its tile rectangle
// r = (x0, y0, x1, y1); r.x = -1 marks a survivor drawn whole without a walk (no tiles checked,
// no split, or a NaN rectangle, which survives: the draw decides).
uint survives(uint k, out uint value, out ivec4 r) {
    vec2 lo, hi;
    r = ivec4(-1);
    if (!splat_rect(k, lo, hi, value)) return 0u;
    if (any(isnan(vec4(lo, hi)))) return 1u;
    if (hi.x < 0.0 || hi.y < 0.0 || lo.x >= u_viewport.x || lo.y >= u_viewport.y) return 0u;
    if (!u_check_tiles) return 1u;
    ivec2 tlo = clamp(ivec2(floor(max(lo, vec2(0.0)))) / TILE_SIZE, ivec2(0), u_tiles - 1);
    ivec2 thi = clamp(ivec2(floor(min(hi, u_viewport))) / TILE_SIZE, ivec2(0), u_tiles - 1);
    if (u_split) {
        r = ivec4(tlo, thi);
        return walk(value, r, false, 0u);
    }
    for (int ty = tlo.y; ty <= thi.y; ++ty)
        for (int tx = tlo.x; tx <= thi.x; ++tx)
            if (is_open(tx, ty)) return 1u;
    return 0u;
}

#define SURVIVOR_BITS 11u   // survivors of a segment (<= 1024) in the scan's low bits

void main() {
    uint l = gl_LocalInvocationID.x;
    uint segment = u_cmd_base + gl_WorkGroupID.x;
    uint first = u_start + gl_WorkGroupID.x * (GROUP * PER_INVOCATION) + l * PER_INVOCATION;
    uint values[PER_INVOCATION];
    ivec4 rects[PER_INVOCATION];
    uint counts[PER_INVOCATION];
    uint n_pieces = 0u, n_survivors = 0u;
    for (uint j = 0u; j < PER_INVOCATION; ++j) {
        uint k = first + j;
        counts[j] = k < u_end ? survives(k, values[j], rects[j]) : 0u;
        n_pieces += counts[j];
        n_survivors += min(counts[j], 1u);
    }
    // Inclusive scan (Hillis-Steele over the work group) of (pieces << 11 | survivors); pieces
    // are capped at PIECE_CAPACITY + 1 an invocation so the sum cannot carry out of 32 bits.
    uint mine = min(n_pieces, uint(PIECE_CAPACITY) + 1u) << SURVIVOR_BITS | n_survivors;
    s_scan[l] = mine;
    barrier();
    for (uint off = 1u; off < GROUP; off <<= 1) {
        uint add = l >= off ? s_scan[l - off] : 0u;
        barrier();
        s_scan[l] += add;
        barrier();
    }
    uint total = s_scan[GROUP - 1u];
    uint before = s_scan[l] - mine;
    bool whole = (total >> SURVIVOR_BITS) > uint(PIECE_CAPACITY);  // overflow: survivors whole
    uint base = segment * uint(PIECE_CAPACITY);
    uint at = base + (whole ? before & ((1u << SURVIVOR_BITS) - 1u) : before >> SURVIVOR_BITS);
    for (uint j = 0u; j < PER_INVOCATION; ++j) {
        if (counts[j] == 0u) continue;
        if (whole || rects[j].x < 0) {
            pieces[3u * at] = values[j];
            pieces[3u * at + 1u] = WHOLE_PIECE;
            pieces[3u * at + 2u] = 0u;
            ++at;
        } else {
            at += walk(values[j], rects[j], true, at);
        }
    }
    if (l == GROUP - 1u) {
        uint c = 5u * segment;
        uint survivors = total & ((1u << SURVIVOR_BITS) - 1u);
        commands[c] = 4u;
        commands[c + 1u] = whole ? survivors : total >> SURVIVOR_BITS;
        commands[c + 2u] = 0u;
        commands[c + 3u] = base;
        commands[c + 4u] = survivors;
    }
}
