// Radix sort, pass step 3 of 3: stable scatter of keys and values by digit.  A key goes to
// hist[d * u_tiles + tile] (the scanned tile offset) + the number of keys of digit d held by
// earlier threads of the tile + the number of earlier keys of digit d in its own thread, so
// equal digits keep their input order (the pass is stable, hence the whole LSD sort).
// Twin: splatgl/gl/radix_sort.py radix_sort_twin().
#include "lib/radix.glsl"

layout(local_size_x = RADIX_GROUP) in;
layout(std430, binding = RADIX_BINDING_KEYS_IN) readonly buffer KeysIn { uint keys_in[]; };
layout(std430, binding = RADIX_BINDING_VALS_IN) readonly buffer ValsIn { uint vals_in[]; };
layout(std430, binding = RADIX_BINDING_KEYS_OUT) writeonly buffer KeysOut { uint keys_out[]; };
layout(std430, binding = RADIX_BINDING_VALS_OUT) writeonly buffer ValsOut { uint vals_out[]; };
layout(std430, binding = RADIX_BINDING_HIST) readonly buffer Hist { uint hist[]; };

shared uint s_scan[RADIX * uint(RADIX_GROUP)];  // [d * RADIX_GROUP + t], then its prefix
shared uint s_part[RADIX_GROUP];

void main() {
    uint t = gl_LocalInvocationID.x;
    uint tile = gl_WorkGroupID.x;
    uint base = tile * TILE_KEYS + t * uint(RADIX_ITEMS);
    uint cnt[RADIX];
    for (uint d = 0u; d < RADIX; ++d) cnt[d] = 0u;
    for (uint i = 0u; i < uint(RADIX_ITEMS); ++i) {
        uint idx = base + i;
        if (idx < u_count) cnt[radix_digit(keys_in[idx])] += 1u;
    }
    for (uint d = 0u; d < RADIX; ++d) s_scan[d * uint(RADIX_GROUP) + t] = cnt[d];
    barrier();
    // Exclusive scan of s_scan (digit-major): thread t scans entries [t * RADIX, t * RADIX + RADIX)
    // after a Hillis-Steele scan of the per-thread sums.
    uint local_v[RADIX];
    uint sum = 0u;
    for (uint j = 0u; j < RADIX; ++j) {
        local_v[j] = s_scan[t * RADIX + j];
        sum += local_v[j];
    }
    s_part[t] = sum;
    barrier();
    for (uint off = 1u; off < uint(RADIX_GROUP); off <<= 1u) {
        uint add = t >= off ? s_part[t - off] : 0u;
        barrier();
        s_part[t] += add;
        barrier();
    }
    uint run = s_part[t] - sum;
    for (uint j = 0u; j < RADIX; ++j) {
        s_scan[t * RADIX + j] = run;
        run += local_v[j];
    }
    barrier();
    for (uint d = 0u; d < RADIX; ++d) {
        uint row = d * uint(RADIX_GROUP);
        cnt[d] = hist[d * u_tiles + tile] + s_scan[row + t] - s_scan[row];
    }
    for (uint i = 0u; i < uint(RADIX_ITEMS); ++i) {
        uint idx = base + i;
        if (idx < u_count) {
            uint key = keys_in[idx];
            uint d = radix_digit(key);
            uint pos = cnt[d];
            cnt[d] = pos + 1u;
            keys_out[pos] = key;
            vals_out[pos] = vals_in[idx];
        }
    }
}
