// Device-resident order (--sort gpu, splatgl/renderers/quad_device.py): the cull and the depth
// keys of every splat, one invocation each.  One twin per cull kind, the same float32 operations
// in the same order (precise: no fused multiply-add), so the same depth bits and decisions:
//   (default) CullKind.FRUSTUM, side planes: splatgl.order.cull.cull_visible(); the peak-alpha
//     bound: splatgl.order.cull.peak_keeps(), float32 on both sides (the same kept splats);
//   CULL_BOX: CullKind.BOX (orthographic), cull_visible()'s box: the planes with z's factor 1;
//   CULL_SPHERE: CullKind.SPHERE (fisheye, equirectangular), splatgl.order.lens_cull.lens_keys():
//     key = distance, kept beyond the near plane; CULL_FISHEYE adds cone_keeps(), CULL_SEAM
//     dispatches 2 u_count invocations, the second u_count being the seam copies (seam_copies()).
//
// Output: staged key j = float bits of z (of the distance) for a kept slot (positive: the bits
// order like the values), 0xFFFFFFFF for a culled one, and each work group's kept count;
// order_scan.comp turns the counts into the groups' first slots and the draw's instance count,
// order_compact.comp writes the kept keys and indices in slot order for the stable sort: the
// CPU order, ties included (a seam copy's index carries WRAP_FLAG, after every plain index, as
// splatgl.order.chunks.keys_pairs lists them).  Nothing comes back to the host.
// Twin: splatgl/order/cull.py cull_visible(), peak_keeps();
//   splatgl/order/lens_cull.py lens_keys(), cone_keeps(), seam_copies().

#include "lib/sqrt_rn.glsl"
#include "lib/div_rn.glsl"

layout(local_size_x = ORDER_GROUP) in;
#include "lib/dispatch.glsl"

struct CullRow {
    vec4 p;     // anchored centre x, y, z; world radius k(o) max_scale (CullData.radius)
    vec4 q;     // max_scale, log(255 opacity) (CullData.cut_log), alive (1/0), faint (1/0)
};
layout(std430, binding = ORDER_BINDING_CULL) readonly buffer Cull { CullRow rows[]; };
layout(std430, binding = ORDER_BINDING_STAGED) writeonly buffer Staged { uint staged[]; };
layout(std430, binding = ORDER_BINDING_BLOCKS) writeonly buffer Blocks { uint blocks[]; };

uniform uint u_count;         // splats (rows of the cull buffer)
uniform uint u_slots;         // invocations: u_count, or 2 u_count with CULL_SEAM
uniform vec3 u_r0;            // rows of the anchored camera's rotation (float32)
uniform vec3 u_r1;
uniform vec3 u_r2;
uniform vec3 u_t;             // its translation (float32)
uniform float u_near;         // near_threshold(near, float32)
uniform vec4 u_plane_x;       // plane_constants(frustum, scale)[0][:4]: a_hi, b_hi, a_lo, b_lo
uniform vec4 u_plane_y;
uniform vec4 u_inside;        // lo_x, hi_x, lo_y, hi_y (plane_constants[:, 4:6])
uniform bool u_peak;          // the peak-alpha bound may cull (a pinhole image)
uniform bool u_antialias;
uniform float u_scale;        // the view's uniform scale (max_scale * scale in the bound)
uniform vec4 u_focal;         // fx, fy, cx, cy of the frustum's camera
uniform vec4 u_image;         // width, height, the Jacobian's clamps (peak_constants32)
uniform float u_aa_floor;     // AA_LOG_FLOOR: log(sqrt(AA_MIN_FACTOR)), float32
uniform vec3 u_lens;          // CULL_SPHERE: float32 cos(angle limit), scale, SEAM_MARGIN_PX / fx

float view_axis(vec3 p, vec3 r, float t) {
    precise float out_ = p.x * r.x;
    out_ += p.y * r.y;
    out_ += p.z * r.z;
    out_ += t;
    return out_;
}

// The planes of one axis (cull_visible's loop): v <= rad b_hi + z a_hi, v >= rad b_lo + z a_lo.
bool planes(float v, float z, float rad, vec4 c) {
    precise float w_hi = rad * c.y;
    precise float u_hi = z * c.x;
    w_hi += u_hi;
    precise float w_lo = rad * c.w;
    precise float u_lo = z * c.z;
    w_lo += u_lo;
    return v <= w_hi && v >= w_lo;
}

// splatgl.order.cull.peak_keeps(): the peak-alpha bound decided in float32 by operations IEEE
// rounds exactly (+ - *, lib/div_rn.glsl's /, roundEven, clamp; precise: no fused
// multiply-add), in its order:
// d^2 / 2 <= lambda (cut_log + max(-a - a^2 / 2, u_aa_floor)), a NaN side keeps.  The CPU's
// decision bit for bit: the same kept splats, so early termination's batches are the CPU's.
bool peak_keeps(vec3 p, float max_scale, float cut_log) {
    float x = p.x, y = p.y, z = p.z;
    float fx = u_focal.x, fy = u_focal.y;
    precise float fx2 = fx * fx;
    precise float fy2 = fy * fy;
    precise float jf2, u, v;
#ifdef CULL_BOX
    jf2 = fx2 + fy2;
    u = fx * x;
    u += u_focal.z;
    v = fy * y;
    v += u_focal.w;
#else
    precise float xz = div_rn(x, z);          // correctly rounded, as NumPy's
    precise float yz = div_rn(y, z);
    float xc = clamp(xz, -u_image.z, u_image.z);
    float yc = clamp(yz, -u_image.w, u_image.w);
    precise float jx = xc * xc;
    jx = 1.0 + jx;
    jx = fx2 * jx;
    precise float jy = yc * yc;
    jy = 1.0 + jy;
    jy = fy2 * jy;
    precise float zz = z * z;
    jf2 = jx + jy;
    jf2 = div_rn(jf2, zz);
    u = fx * xz;
    u += u_focal.z;
    v = fy * yz;
    v += u_focal.w;
#endif
    precise float ms = max_scale * u_scale;
    precise float lam = jf2 * ms;
    lam = lam * ms;
    lam = lam + LOW_PASS;
    precise float nu = u - 0.5;
    nu = clamp(roundEven(nu), 0.0, u_image.x - 1.0) + 0.5;
    precise float nv = v - 0.5;
    nv = clamp(roundEven(nv), 0.0, u_image.y - 1.0) + 0.5;
    precise float du = u - nu;
    precise float dv = v - nv;
    precise float d2 = du * du;
    precise float dvv = dv * dv;
    d2 += dvv;
    precise float lhs = 0.5 * d2;
    precise float level = cut_log;
    if (u_antialias) {
        precise float a = div_rn(LOW_PASS, lam);
        precise float h = 0.5 * a;
        h = h * a;
        h = a + h;
        level = level + max(-h, u_aa_floor);
    }
    precise float rhs = level * lam;
    if (isnan(lhs) || isnan(rhs)) return true;   // never cull on a NaN side
    return lhs <= rhs;
}

shared uint group_kept;

#ifdef CULL_SPHERE
// lens_keys(): the distance beyond the near plane, the fisheye's cone, the seam copy.
bool cull(uint j) {
    bool copy = j >= u_count;
    uint i = copy ? j - u_count : j;
    CullRow row = rows[i];
    vec3 p = row.p.xyz;
    float x = view_axis(p, u_r0, u_t.x);
    float y = view_axis(p, u_r1, u_t.y);
    float z = view_axis(p, u_r2, u_t.z);
    precise float d2 = x * x;
    precise float yy = y * y;
    d2 += yy;
    precise float zz = z * z;
    d2 += zz;
    float d = sqrt_rn(d2);
    bool keep = d > u_near && row.q.z != 0.0;
#ifdef CULL_FISHEYE
    precise float off = d * u_lens.x;                 // cone_keeps: z - d cos_limit >= 0
    off = z - off;
    keep = keep && off >= 0.0;
#endif
#ifdef CULL_SEAM
    if (copy && keep) {                               // seam_copies: |x| < reach, z < reach
        precise float reach = row.p.w * u_lens.y;
        precise float margin = d * u_lens.z;
        reach += margin;
        keep = abs(x) < reach && z < reach;
    }
#endif
    staged[j] = keep ? floatBitsToUint(d) : 0xFFFFFFFFu;
    return keep;
}
#else
bool cull(uint i) {
    CullRow row = rows[i];
    vec3 p = row.p.xyz;
    float rad = row.p.w;
    float z = view_axis(p, u_r2, u_t.z);
    bool keep = z > u_near && row.q.z != 0.0;
    bool inside = true;
    float vx = view_axis(p, u_r0, u_t.x);
    float vy = view_axis(p, u_r1, u_t.y);
#ifdef CULL_BOX
    float zp = 1.0;     // plane_constants' box: z's factor 1
#else
    float zp = z;
#endif
    if (keep) {
        keep = planes(vx, zp, rad, u_plane_x) && planes(vy, zp, rad, u_plane_y);
        precise float ex_lo = zp * u_inside.x;
        precise float ex_hi = zp * u_inside.y;
        precise float ey_lo = zp * u_inside.z;
        precise float ey_hi = zp * u_inside.w;
        inside = vx <= ex_hi && vx >= ex_lo && vy <= ey_hi && vy >= ey_lo;
    }
    if (keep && u_peak && (u_antialias || !inside || row.q.w != 0.0))
        keep = peak_keeps(vec3(vx, vy, z), row.q.x, row.q.y);
    staged[i] = keep ? floatBitsToUint(z) : 0xFFFFFFFFu;
    return keep;
}
#endif

void main() {
    if (gl_LocalInvocationIndex == 0u) group_kept = 0u;
    barrier();
    uint i = linear_invocation();
    if (i < u_slots && cull(i)) atomicAdd(group_kept, 1u);
    barrier();
    if (gl_LocalInvocationIndex == 0u) blocks[linear_group()] = group_kept;
}
