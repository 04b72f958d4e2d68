"""Early termination with the device-resident order (``--sort gpu --early-stop on|auto``).

The CPU order's early termination (:mod:`splatgl.renderers.batches`) decides on the host, from
the sorted count and a coverage estimate it reads back: whether to batch, the schedule, and
:func:`~splatgl.renderers.early_stop.batch_bounds`.  With the device order the host never learns
the count, so ``shaders/stop_plan.comp`` (one invocation) makes those decisions on the device
with the same float64 operations in the same order (the host adds the coverage partial sums in
index order, as it does), and the host issues the most passes any count up to the order's
slots can need (:func:`max_batches`, :func:`batch_groups`), each sized from the plan:

1. ``stop_plan.comp`` (PLAN_COVERAGE): coverage.comp's dispatch size for the kept count;
2. ``coverage.comp`` (DEVICE_COUNT), dispatched from it: the partial sums;
3. ``stop_plan.comp``: the estimate, AUTO's rule, the schedule, the bounds; per batch the mark
   pass's indirect draw (no instance where the batch is empty) and stop_tiles.comp's indirect
   dispatch size (0 groups there);
4. per batch: the mark and the tiles (b > 0, indirect), ``occlusion_cull.comp``
   (DEVICE_BATCHES: its slots from the plan; groups past the batch's end write empty commands)
   and one multi-draw-indirect over the batch's command range.

Not batched (AUTO below its rule), batch 0 is every kept slot and nothing runs between
batches: the occlusion cull then drops only splats off the viewport, which draw nothing, so the
image is the plain draw's.  Images are identical to early termination with the CPU order
(tests/renderers/test_quad_device_stop.py); nothing is read back (the splats the occlusion cull
dropped and the batches drawn are not known on the host: :class:`QuadTimes` reports 0 and the
batches issued).
"""

from __future__ import annotations

import dataclasses
import math

import moderngl
import numpy as np

from ..constants import (EARLY_STOP_FINE_QUAD_FRAGMENTS, EARLY_STOP_MIN_OVERDRAW,
                         EARLY_STOP_MIN_QUAD_FRAGMENTS, TILE_SIZE)
from ..gl.bindings import (ACCUM_UNIT, BINDING_COMMANDS, BINDING_COVERAGE, BINDING_DEVICE_COUNT, BINDING_ORDER,
                           BINDING_STOP_PLAN, COVERAGE_GROUP, STOP_TILES_GROUP)
from ..gl import dispatch
from ..gl.transfers import transfers
from ..scene.settings import EarlyStop
from .early_stop import (COARSE_SCHEDULE, COMMAND_BYTES, COVERAGE_MIN_INVOCATIONS,
                         COVERAGE_SLOTS_PER_INVOCATION, FINE_SCHEDULE, MAX_BATCH, MIN_BATCH,
                         SEGMENT)

#: Uints of the plan per batch (mark command 5, tiles dispatch 3, bounds 2), then after the
#: batches: coverage dispatch 3, batched, fine, batches, the estimate's two words.
PLAN_PER_BATCH = 10
PLAN_TAIL = 8


def max_batches(slots: int) -> int:
    """An upper bound of the batches :func:`~splatgl.renderers.early_stop.batch_bounds` makes
    for any count up to ``slots`` under either schedule: the first batch holds at least the
    share ``f`` of the count and each next one ``g`` times as many (less one for the rounding
    down), so ``K`` batches with ``(g^K - 1) / (g - 1) >= 1 / f + K`` reach the count, plus one
    batch per ``MAX_BATCH`` slots where the cap holds them back."""
    most = 1
    for share, growth in (COARSE_SCHEDULE, FINE_SCHEDULE):
        k = 1
        while (growth ** k - 1.0) / (growth - 1.0) < 1.0 / share + k:
            k += 1
        most = max(most, k + 1 + -(-slots // MAX_BATCH))
    return most


def batch_groups(slots: int, batches: int) -> list[int]:
    """Occlusion-cull groups (draw commands) each batch can need for a count up to ``slots``:
    batch 0 all the slots (the not-batched frame draws every slot in it), batch b > 0 at most
    ``min(MAX_BATCH, first * g^b)`` with ``first`` the larger schedule's first batch."""
    out = [max(1, -(-slots // SEGMENT))]
    for b in range(1, batches):
        most = max(max(MIN_BATCH, math.ceil(slots * share)) * max(growth, 1.0) ** b
                   for share, growth in (COARSE_SCHEDULE, FINE_SCHEDULE))
        out.append(max(1, -(-int(min(MAX_BATCH, slots, most + 1)) // SEGMENT)))
    return out


def draw(batches, view, target, prog: moderngl.Program, frame, device, resources) -> None:
    """Draw the device order's kept slots (``device``: :class:`~splatgl.renderers.quad_device.
    DeviceOrder`, run) into ``target`` (bound, cleared, blending set up) with early
    termination (``batches``: the renderer's :class:`~splatgl.renderers.batches.Batches`, mode
    ON or AUTO; ``prog``: the batched draw program)."""
    ctx, stop, programs = batches.ctx, batches.passes, batches.programs
    counter = transfers(ctx)
    slots, width, height = device.slots, view.width, view.height
    n_b = max_batches(slots)
    groups = batch_groups(slots, n_b)
    plan = stop._grow("plan", 4 * (PLAN_PER_BATCH * n_b + PLAN_TAIL))
    grid = (-(-width // TILE_SIZE), -(-height // TILE_SIZE))
    device.command.bind_to_storage_buffer(BINDING_DEVICE_COUNT)
    plan.bind_to_storage_buffer(BINDING_STOP_PLAN)
    device.values.bind_to_storage_buffer(BINDING_ORDER)
    extra = frame.extra + (("DEVICE_COUNT", 1),)
    planners = [programs.cache.compute("stop_plan.comp", {"PLAN_COVERAGE": 1}),
                programs.cache.compute("stop_plan.comp")]
    for prog_plan in planners:
        _plan_uniforms(prog_plan, batches.mode, n_b, width, height,
                       -(-grid[0] * grid[1] // STOP_TILES_GROUP))
        counter.uniforms(prog_plan)
    planners[0].run(group_x=1)
    ctx.memory_barrier()
    cov = programs.rect(view, "coverage.comp", dataclasses.replace(frame, extra=extra))
    view.set_uniforms(cov)
    counter.uniforms(cov)
    cov_groups = max(COVERAGE_MIN_INVOCATIONS, -(-slots // COVERAGE_SLOTS_PER_INVOCATION))
    stop._grow("partial", 4 * COVERAGE_GROUP * -(-cov_groups // COVERAGE_GROUP)
               ).bind_to_storage_buffer(BINDING_COVERAGE)
    dispatch.run_indirect(cov, plan, 4 * PLAN_PER_BATCH * n_b, -(-cov_groups // COVERAGE_GROUP),
                          f"{slots} sorted splats")
    ctx.memory_barrier()
    planners[1].run(group_x=1)
    ctx.memory_barrier()
    stop.prepare(slots, [0, slots], width, height)
    stop._grow("commands", COMMAND_BYTES * sum(groups)).bind_to_storage_buffer(BINDING_COMMANDS)
    cull = programs.rect(view, "occlusion_cull.comp",
                         dataclasses.replace(frame, extra=frame.extra + (("DEVICE_BATCHES", 1),)))
    view.set_uniforms(cull)
    cull["u_tiles"].value = grid
    tiles = programs.cache.compute("stop_tiles.comp")
    tiles["u_size"].value = (width, height)
    tiles["u_tiles"].value = grid
    mark = programs.cache.program("stop_mark.vert", "stop_mark.frag")
    mark_vao = stop._mark_vao
    if mark_vao is None or mark_vao.program is not mark:
        mark_vao = stop._mark_vao = ctx.vertex_array(mark, [])
    vao = resources.vertex_array(prog, stop.survivors)
    ctx.depth_func = "<"
    ctx.enable(moderngl.DEPTH_TEST)
    first = 0
    for b, n in enumerate(groups):
        if b > 0:   # stop_mark and stop_tiles, drawing and dispatching nothing past the end
            ctx.disable(moderngl.BLEND)
            target.texture.use(ACCUM_UNIT)
            target.mask_fbo.use()
            target.mask_fbo.depth_mask = True
            mark_vao.render_indirect(plan, moderngl.TRIANGLES, count=1, first=b)
            dispatch.run_indirect(tiles, plan, 4 * (5 * n_b + 3 * b),
                                  -(-grid[0] * grid[1] // STOP_TILES_GROUP), "tiles")
            ctx.memory_barrier()
        cull["u_bounds_at"].value = 8 * n_b + 2 * b
        cull["u_cmd_base"].value = first
        cull["u_check_tiles"].value = b > 0
        counter.uniforms(cull)
        dispatch.run(cull, n, f"{slots} sorted splats")
        ctx.memory_barrier()
        target.fbo.use()
        target.fbo.depth_mask = False
        ctx.enable(moderngl.BLEND)
        vao.render_indirect(stop.commands, moderngl.TRIANGLE_STRIP, count=n, first=first)
        first += n
    counter.uniforms(tiles)
    batches.batches, batches.occlusion_culled, batches.fragments_estimate = n_b, 0, 0


def _plan_uniforms(prog, mode: EarlyStop, n_b: int, width: int, height: int,
                   tile_groups: int) -> None:
    values = {
        "u_max_batches": n_b, "u_min_invocations": COVERAGE_MIN_INVOCATIONS,
        "u_slots_per_invocation": COVERAGE_SLOTS_PER_INVOCATION,
        "u_always": mode is EarlyStop.ON,
        "u_fine_per_quad": float(EARLY_STOP_FINE_QUAD_FRAGMENTS),
        "u_min_per_quad": float(EARLY_STOP_MIN_QUAD_FRAGMENTS),
        "u_min_fragments": float(EARLY_STOP_MIN_OVERDRAW * width * height),
        "u_schedules": (*COARSE_SCHEDULE, *FINE_SCHEDULE),
        "u_min_batch": MIN_BATCH, "u_max_batch": MAX_BATCH, "u_tile_groups": tile_groups,
    }
    for name, value in values.items():
        if name in prog:
            prog[name].value = value


def plan_state(batches, slots: int) -> dict[str, object]:
    """The last device plan's decisions, read back (for tests: a synchronisation point)."""
    n_b = max_batches(slots)
    words = np.frombuffer(batches.passes.plan.read(), np.uint32)
    tail = words[PLAN_PER_BATCH * n_b:PLAN_PER_BATCH * n_b + PLAN_TAIL]
    bounds = words[8 * n_b:10 * n_b].reshape(n_b, 2)
    return {"batched": bool(tail[3]), "fine": bool(tail[4]), "batches": int(tail[5]),
            "estimate": float(tail[6:8].view(np.float64)[0]),
            "bounds": [0] + [int(e) for s, e in bounds[:int(tail[5])]]}
