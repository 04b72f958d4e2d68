"""The quad path's draw in batches, and early termination's GPU passes between them.

A frame's sorted splats are drawn in batches: with early termination off (or ``auto`` on a view
that does not pay) in plain batches of at most :data:`~splatgl.renderers.early_stop.MAX_BATCH`
splats; with it on, in its schedule, with the mark, tile and occlusion-cull passes between
batches (:class:`EarlyStopPasses`; the algorithm, its accuracy and its NumPy twins are in
:mod:`splatgl.renderers.early_stop`).  :class:`Batches` decides per frame and draws; a hook
called after each batch may raise KeyboardInterrupt to abandon the frame.  With the
device-resident order the same batches are planned and drawn on the device
(:mod:`splatgl.renderers.early_stop_device`).
"""

from __future__ import annotations

import moderngl
import numpy as np

from ..constants import (EARLY_STOP_FINE_QUAD_FRAGMENTS, EARLY_STOP_MIN_OVERDRAW,
                         EARLY_STOP_MIN_QUAD_FRAGMENTS, TILE_SIZE)
from ..gl.bindings import (ACCUM_UNIT, BINDING_COMMANDS, BINDING_COVERAGE, BINDING_STOP_TILES,
                           BINDING_SURVIVORS, COVERAGE_GROUP, STOP_TILES_GROUP)
from ..gl import dispatch
from ..gl.buffers import GrowableBuffer
from ..gl.transfers import transfers
from ..gl.device_class import of_context, resolve_early_stop
from ..scene.settings import EarlyStop
from .early_stop import (COARSE_SCHEDULE, COMMAND_BYTES, COVERAGE_MIN_INVOCATIONS,
                         COVERAGE_SLOTS_PER_INVOCATION, FINE_SCHEDULE, MAX_BATCH, SEGMENT,
                         BatchHook, batch_bounds, plain_bounds)


class EarlyStopPasses:
    """The GL objects and passes of early termination for one quad renderer.

    Buffers grow as needed; :meth:`release` frees them.  The caller binds the scene, the order
    (BINDING_ORDER) and, for the pre-pass variant, the prepared buffer (BINDING_PREPARED)
    before :meth:`cull`.
    """

    def __init__(self, ctx: moderngl.Context, programs):
        self.ctx = ctx
        self.programs = programs
        self.tiles: moderngl.Buffer | None = None
        self.survivors: moderngl.Buffer | None = None
        self.commands: moderngl.Buffer | None = None
        self.partial: moderngl.Buffer | None = None
        self._buffers: dict[str, GrowableBuffer] = {}
        self._mark_vao: moderngl.VertexArray | None = None

    def _grow(self, name: str, size: int) -> moderngl.Buffer:
        if name not in self._buffers:
            self._buffers[name] = GrowableBuffer(self.ctx)
        buf = self._buffers[name].ensure(size)
        setattr(self, name, buf)
        return buf

    def prepare(self, count: int, bounds: list[int], width: int, height: int) -> int:
        """Size the buffers for ``count`` sorted splats in ``bounds``; returns the command count."""
        n_cmd = sum(-(-(e - s) // SEGMENT) for s, e in zip(bounds[:-1], bounds[1:]))
        gw, gh = -(-width // TILE_SIZE), -(-height // TILE_SIZE)
        self._grow("tiles", 4 * gw * gh).bind_to_storage_buffer(BINDING_STOP_TILES)
        self.tiles.clear()  # all open until the first mark
        self._grow("survivors", 4 * count)
        self._grow("commands", COMMAND_BYTES * n_cmd)
        self.survivors.bind_to_storage_buffer(BINDING_SURVIVORS)
        self.commands.bind_to_storage_buffer(BINDING_COMMANDS)
        return n_cmd

    def mark(self, accum: moderngl.Texture, mask_fbo: moderngl.Framebuffer) -> None:
        """Write depth 0 into ``mask_fbo`` where ``accum``'s T < T_MIN (depth test LESS on)."""
        prog = self.programs.program("stop_mark.vert", "stop_mark.frag")
        if self._mark_vao is None or self._mark_vao.program is not prog:
            self._mark_vao = self.ctx.vertex_array(prog, [])
        accum.use(ACCUM_UNIT)
        mask_fbo.use()
        mask_fbo.depth_mask = True
        self._mark_vao.render(moderngl.TRIANGLES, vertices=3)

    def reduce_tiles(self, accum: moderngl.Texture, width: int, height: int) -> None:
        """stop_tiles.comp: one stop word per tile into the tiles buffer (BINDING_STOP_TILES)."""
        comp = self.programs.compute("stop_tiles.comp")
        grid = (-(-width // TILE_SIZE), -(-height // TILE_SIZE))
        comp["u_size"].value = (width, height)
        comp["u_tiles"].value = grid
        accum.use(ACCUM_UNIT)
        dispatch.run(comp, -(-grid[0] * grid[1] // STOP_TILES_GROUP), f"{grid[0] * grid[1]} tiles")

    def cull(self, comp: moderngl.ComputeShader, start: int, end: int, cmd_base: int,
             width: int, height: int, check_tiles: bool) -> int:
        """occlusion_cull.comp over slots [start, end); returns the commands written."""
        groups = -(-(end - start) // SEGMENT)
        comp["u_start"].value = start
        comp["u_end"].value = end
        comp["u_cmd_base"].value = cmd_base
        comp["u_tiles"].value = (-(-width // TILE_SIZE), -(-height // TILE_SIZE))
        comp["u_check_tiles"].value = check_tiles
        dispatch.run(comp, groups, f"{end - start} sorted splats")
        return groups

    def coverage(self, comp: moderngl.ComputeShader, count: int) -> float:
        """coverage.comp over the ``count`` sorted slots: the estimated fragments (the caller
        binds the order, the prepared quads or the scene, and sets the camera uniforms)."""
        invocations = max(COVERAGE_MIN_INVOCATIONS, -(-count // COVERAGE_SLOTS_PER_INVOCATION))
        groups = -(-invocations // COVERAGE_GROUP)
        partial = self._grow("partial", 4 * groups * COVERAGE_GROUP)
        partial.bind_to_storage_buffer(BINDING_COVERAGE)
        comp["u_count"].value = count
        dispatch.run(comp, groups, f"{count} sorted splats")
        self.ctx.memory_barrier()
        sums = np.frombuffer(partial.read(size=4 * groups * COVERAGE_GROUP), np.float32)
        transfers(self.ctx).read(sums.nbytes)
        # added in float64 in index order: shaders/stop_plan.comp adds them so on the device
        return float(np.cumsum(sums, dtype=np.float64)[-1])

    def survivor_count(self, n_cmd: int) -> int:
        """Sum of the instance counts of the first ``n_cmd`` commands (after the frame)."""
        if n_cmd == 0:
            return 0
        cmds = np.frombuffer(self.commands.read(size=n_cmd * COMMAND_BYTES), np.uint32)
        transfers(self.ctx).read(cmds.nbytes)
        return int(cmds.reshape(n_cmd, COMMAND_BYTES // 4)[:, 1].sum())

    def release(self) -> None:
        for buf in self._buffers.values():
            buf.release()
        self._buffers.clear()
        if self._mark_vao is not None:
            self._mark_vao.release()
        self.tiles = self.survivors = self.commands = self.partial = self._mark_vao = None


class Batches:
    """The draw of one quad renderer in batches (see the module doc).

    ``resources``: the renderer's :class:`~splatgl.renderers.quad_gpu.QuadResources` (the
    sorted index buffer and the vertex arrays that read it); ``programs``: its
    :class:`~splatgl.renderers.quad_programs.QuadPrograms`.  After a frame: :attr:`batched`,
    :attr:`batches`, :attr:`fragments_estimate` and :attr:`occlusion_culled`.
    """

    def __init__(self, ctx: moderngl.Context, mode: EarlyStop, resources, programs):
        #: ``mode`` on this device: AUTO is ON on a hardware GPU (measured on one H100,
        #: docs/gpu.md), the coverage rule below on a software rasteriser (tuned on llvmpipe).
        mode = resolve_early_stop(mode, of_context(ctx))
        self.ctx, self.mode, self.res, self.programs = ctx, mode, resources, programs
        self.passes = EarlyStopPasses(ctx, programs.cache) if mode is not EarlyStop.OFF else None
        #: Whether the current frame draws in early-termination batches (:meth:`decide`), its
        #: coverage estimate (fragments; 0: none made), the batches drawn, the splats the
        #: occlusion cull dropped.
        self.batched = mode is EarlyStop.ON
        self.fragments_estimate = 0
        self.batches = 1
        self.occlusion_culled = 0
        self._schedule = COARSE_SCHEDULE
        #: Longest plain batch (splats): a smaller one lets ``on_batch`` run (and interrupt the
        #: frame) sooner; the image is the same whatever the batches.
        self.max_batch = MAX_BATCH

    def decide(self, view, count: int, frame) -> bool:
        """Whether this frame draws in early-termination batches, and their schedule.

        OFF: never.  ON and AUTO first estimate the fragments a plain draw would rasterise
        (coverage.comp; needs the order, scene and prepared quads bound).  ON always batches,
        AUTO from EARLY_STOP_MIN_QUAD_FRAGMENTS fragments per quad and EARLY_STOP_MIN_OVERDRAW
        per image pixel; both take the fine schedule from EARLY_STOP_FINE_QUAD_FRAGMENTS per
        quad, else the coarse one (constants.py)."""
        self.fragments_estimate = 0
        if self.mode is EarlyStop.OFF or count == 0:
            self.batched = False
            return False
        self.res.index.bind()
        comp = self.programs.rect(view, "coverage.comp", frame)
        view.set_uniforms(comp)
        estimate = self.passes.coverage(comp, count)
        self.fragments_estimate = int(round(estimate))
        fine = estimate >= EARLY_STOP_FINE_QUAD_FRAGMENTS * count
        self._schedule = FINE_SCHEDULE if fine else COARSE_SCHEDULE
        if self.mode is EarlyStop.ON:
            self.batched = True
        else:
            self.batched = (estimate >= EARLY_STOP_MIN_QUAD_FRAGMENTS * count
                            and estimate >= EARLY_STOP_MIN_OVERDRAW * view.width * view.height)
        return self.batched

    def draw(self, view, target, prog: moderngl.Program, count: int, frame,
             on_batch: BatchHook | None) -> None:
        """Draw the ``count`` sorted splats into ``target`` (bound, cleared, blending set up)."""
        self.occlusion_culled = 0
        if not self.batched:
            bounds = plain_bounds(count, self.max_batch)
            self.batches = len(bounds) - 1
            for start, end in zip(bounds[:-1], bounds[1:]):
                self.res.draw_range(prog, start, end - start)
                if on_batch is not None:
                    self.ctx.finish()
                    on_batch(end, count)
            return
        # Early termination (splatgl/renderers/early_stop.py): mark, reduce to tiles, cull,
        # draw the survivors.
        stop, ctx = self.passes, self.ctx
        width, height = view.width, view.height
        bounds = batch_bounds(count, *self._schedule)
        self.batches = len(bounds) - 1
        n_cmd = stop.prepare(count, bounds, width, height)
        cull_prog = self.programs.rect(view, "occlusion_cull.comp", frame)
        view.set_uniforms(cull_prog)
        self.res.index.bind()
        vao = self.res.vertex_array(prog, stop.survivors)
        ctx.depth_func = "<"
        ctx.enable(moderngl.DEPTH_TEST)
        first = 0
        for b, (start, end) in enumerate(zip(bounds[:-1], bounds[1:])):
            if b > 0:
                ctx.disable(moderngl.BLEND)
                stop.mark(target.texture, target.mask_fbo)
                stop.reduce_tiles(target.texture, width, height)
                ctx.memory_barrier()
            groups = stop.cull(cull_prog, start, end, first, width, height, check_tiles=b > 0)
            ctx.memory_barrier()
            target.fbo.use()
            target.fbo.depth_mask = False
            ctx.enable(moderngl.BLEND)
            # The batch's commands (one per SEGMENT slots) drawn max_batch slots at a time, in
            # order: the same primitives in the same order as one draw, so the same image, and
            # on_batch can abandon a long batch (the early-stop decisions stay per batch).
            step = max(1, self.max_batch // SEGMENT)
            for sub in range(0, groups, step):
                n = min(step, groups - sub)
                vao.render_indirect(stop.commands, moderngl.TRIANGLE_STRIP, count=n, first=first + sub)
                if on_batch is not None and sub + n < groups:
                    ctx.finish()
                    on_batch(min(end, start + (sub + n) * SEGMENT), count)
            first += groups
            if on_batch is not None:
                ctx.finish()
                on_batch(end, count)
        self.occlusion_culled = count - stop.survivor_count(n_cmd)

    def release(self) -> None:
        if self.passes is not None:
            self.passes.release()
