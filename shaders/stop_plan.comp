// Early termination with the device-resident order (splatgl/renderers/early_stop_device.py):
// one invocation makes, from the kept count in the order's draw command (never read back), the
// decisions the host makes for the CPU order, with the same float64 operations in the same order.
// PLAN_COVERAGE: coverage.comp's dispatch size for that count (Batches.decide's invocations).
// Otherwise, after coverage.comp: the estimate (its partial sums added in float64 in index
// order, as Batches.decide adds them), AUTO's rule and the schedule (fine or coarse), and
// batch_bounds() of the count; per batch b of u_max_batches: its slots [start, end), the mark
// pass's indirect draw command (one triangle instance where the batch exists and b > 0, else
// none) and stop_tiles.comp's indirect dispatch size (0 groups where it does not).  Not
// batched: batch 0 is every kept slot (no pass between batches runs; the occlusion cull drops
// only splats that would draw nothing).  Plan layout (uints, u_max_batches = B): marks 5 B,
// tile dispatches 3 B, bounds 2 B, coverage dispatch 3, then batched, fine, batches and the
// estimate's two words (for tests).
// Twin: splatgl/renderers/early_stop.py batch_bounds(); splatgl/renderers/batches.py Batches.decide().

layout(local_size_x = STOP_PLAN_GROUP) in;
layout(std430, binding = BINDING_DEVICE_COUNT) readonly buffer DeviceCount { uint device_command[]; };
layout(std430, binding = BINDING_STOP_PLAN) buffer Plan { uint plan[]; };
#ifndef PLAN_COVERAGE
layout(std430, binding = BINDING_COVERAGE) readonly buffer Partial { float partial[]; };
#endif

uniform uint u_max_batches;
uniform uint u_min_invocations;      // COVERAGE_MIN_INVOCATIONS
uniform uint u_slots_per_invocation; // COVERAGE_SLOTS_PER_INVOCATION
uniform bool u_always;               // --early-stop on: batched whatever the estimate
uniform double u_fine_per_quad;      // EARLY_STOP_FINE_QUAD_FRAGMENTS
uniform double u_min_per_quad;       // EARLY_STOP_MIN_QUAD_FRAGMENTS
uniform double u_min_fragments;      // EARLY_STOP_MIN_OVERDRAW * width * height (host float64)
uniform dvec4 u_schedules;           // COARSE_SCHEDULE, FINE_SCHEDULE: (first share, growth) each
uniform uint u_min_batch;            // MIN_BATCH
uniform uint u_max_batch;            // MAX_BATCH
uniform uint u_tile_groups;          // stop_tiles.comp's work groups for the image

void main() {
    uint count = device_command[1];
    uint at_cov = 10u * u_max_batches;
#ifdef PLAN_COVERAGE
    uint inv = max(u_min_invocations, (count + u_slots_per_invocation - 1u) / u_slots_per_invocation);
    plan[at_cov] = (inv + uint(COVERAGE_GROUP) - 1u) / uint(COVERAGE_GROUP);
    plan[at_cov + 1u] = 1u;
    plan[at_cov + 2u] = 1u;
#else
    uint total = plan[at_cov] * uint(COVERAGE_GROUP);
    double estimate = 0.0LF;
    for (uint i = 0u; i < total; ++i) estimate += double(partial[i]);
    double n = double(count);
    bool fine = estimate >= u_fine_per_quad * n;
    bool batched = count > 0u && (u_always
                                  || (estimate >= u_min_per_quad * n && estimate >= u_min_fragments));
    double share = fine ? u_schedules.z : u_schedules.x;
    double growth = max(fine ? u_schedules.w : u_schedules.y, 1.0LF);
    double size = double(max(u_min_batch, uint(ceil(n * share))));
    uint end = 0u, batches = 0u;
    for (uint b = 0u; b < u_max_batches; ++b) {
        uint start = end;
        if (end < count) {
            uint step = batched ? uint(min(double(u_max_batch), max(1.0LF, size))) : count;
            end = (b + 1u == u_max_batches || count - end <= step) ? count : end + step;
            size *= growth;
            batches = b + 1u;
        }
        bool between = b > 0u && start < end;   // the passes before a batch that exists
        plan[5u * b] = 3u;
        plan[5u * b + 1u] = between ? 1u : 0u;
        plan[5u * b + 2u] = 0u;
        plan[5u * b + 3u] = 0u;
        plan[5u * b + 4u] = 0u;
        plan[5u * u_max_batches + 3u * b] = between ? u_tile_groups : 0u;
        plan[5u * u_max_batches + 3u * b + 1u] = 1u;
        plan[5u * u_max_batches + 3u * b + 2u] = 1u;
        plan[8u * u_max_batches + 2u * b] = start;
        plan[8u * u_max_batches + 2u * b + 1u] = end;
    }
    plan[at_cov + 3u] = batched ? 1u : 0u;
    plan[at_cov + 4u] = fine ? 1u : 0u;
    plan[at_cov + 5u] = batches;
    uvec2 words = unpackDouble2x32(estimate);
    plan[at_cov + 6u] = words.x;
    plan[at_cov + 7u] = words.y;
#endif
}
