"""The graphics-API quad path (DESIGN.md section 3): cull -> sort -> instanced quads -> blend.

Per view, only the sorted index buffer is uploaded; the scene's storage buffers are uploaded
once.  The vertex stage (shaders/quad.vert) evaluates SH colour and the 2D covariance and sizes
the quad; the fragment stage (shaders/quad.frag) evaluates the conic opacity.  Blending is
front to back, (ONE_MINUS_DST_ALPHA, ONE), into a cleared (0, 0, 0, 0) target.  With early
termination (``early_stop`` ON, or AUTO on a view of large, overlapping quads) the sorted splats
are drawn in batches and pixels that are already opaque stop receiving fragments (splatgl/renderers/early_stop.py);
a draw calls ``on_batch(done, total)`` between batches, which may raise KeyboardInterrupt to
abandon the frame.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import moderngl
import numpy as np

from ..cameras.camera import Camera
from ..constants import (EARLY_STOP_FINE_QUAD_FRAGMENTS, EARLY_STOP_MIN_OVERDRAW,
                         EARLY_STOP_MIN_QUAD_FRAGMENTS)
from ..order.cull import CullData
from ..order.chunks import ChunkedCull, keys_order, keys_pairs
from ..gl.radix_sort import RadixSorter, device_depth_sort
from ..order.lens_cull import lens_visible_keys
from .early_stop import (COARSE_SCHEDULE, COMMAND_BYTES, FINE_SCHEDULE, BatchHook, EarlyStopPasses,
                         batch_bounds, plain_bounds)
from ..gl.scene_buffers import SceneBuffers
from ..gl.shaders import ProgramCache
from ..gl.targets import ColorTarget
from ..output.layers import RenderOutput
from ..cameras.view import anchored_camera, near_threshold
from ..twins.project import to_camera
from ..model.scene import Scene, SplatKind
from ..model.settings import (EarlyStop, Preprocess, QuadExtent, RenderSettings, SortKey,
                              resolve_near)
from ..order.sort import bucket_sort, depth_sort

#: Storage bindings of the compute pre-pass (after the scene's 0..4).
BINDING_ORDER, BINDING_PREPARED = 5, 6
#: Storage binding of the benchmark's fragment counters (shaders/quad.frag, COUNT_FRAGMENTS).
BINDING_FRAGMENT_COUNTS = 7
#: Storage binding of the pre-pass's per-slot opacity weights (OPACITY_WEIGHT; after early
#: termination's 8..10): the level-of-detail blend, splatgl/lod/render.py.
BINDING_OPACITY_WEIGHT = 11
#: Bytes per splat of the pre-pass output (4 vec4, see shaders/quad_prepass.comp).
PREPARED_BYTES = 64
#: Work-group size of shaders/quad_prepass.comp.
PREPASS_GROUP = 128


@dataclass(frozen=True)
class QuadTimes:
    """Wall-clock seconds of each stage of one quad-path frame (``prepass`` is 0 unless the
    per-splat math runs in the compute pre-pass); ``drawn`` counts the instances drawn.
    ``cull`` includes writing the sort keys; ``sort`` is the sort of those keys."""

    cull: float
    sort: float
    upload: float
    prepass: float
    draw: float
    readback: float
    drawn: int = 0
    #: Splats the early-termination occlusion cull dropped (0 with early_stop off).
    occlusion_culled: int = 0
    #: Seconds this frame spent building the scene's chunked cull data (the first culled view
    #: only; :class:`splatgl.order.chunks.ChunkedCull`), apart from the per-view ``cull``.
    cull_build: float = 0.0
    #: ``--early-stop auto``: seconds of the coverage estimate (shaders/coverage.comp), the
    #: fragments it estimated (0: no estimate), and the draw's batches; ``batched``: whether
    #: the draw ran early termination (with OFF, or AUTO below its threshold, it did not).
    coverage: float = 0.0
    fragments_estimate: int = 0
    batches: int = 1
    batched: bool = False

    @property
    def total(self) -> float:
        return (self.cull_build + self.cull + self.sort + self.upload + self.prepass + self.coverage
                + self.draw + self.readback)


def composite(rgba: np.ndarray, background: tuple[float, float, float]) -> np.ndarray:
    """``C + (1 - A) bg`` on an (H, W, 4) premultiplied image; alpha is kept as A.

    Returns a new array.  Per channel and skipping zero channels: broadcasting over the
    (H, W, 3) view measured 5x slower (35 ms against 7 ms at 1280x720).
    """
    out = np.array(rgba, np.float32, copy=True)
    transmittance = None
    for c, value in enumerate(background):
        if value:
            if transmittance is None:
                transmittance = 1.0 - rgba[..., 3]
            out[..., c] += transmittance * np.float32(value)
    return out


def set_camera_uniforms(prog: moderngl.Program, camera: Camera, near: float,
                        anchor: np.ndarray | None = None) -> None:
    """Write the uniforms of shaders/lib/camera.glsl that ``prog`` uses.

    ``anchor``: the scene's anchor when the storage buffers hold ``means - anchor``
    (:class:`SceneBuffers`); it is folded into the translation in float64.
    """
    if anchor is not None:
        camera = anchored_camera(camera, anchor)
    tx, ty = camera.tan_half_fov
    values = {
        "u_view_rot": tuple(camera.rotation.astype(np.float32).T.ravel()),  # column-major
        "u_view_trans": tuple(camera.translation.astype(np.float32)),
        "u_cam_center": tuple(camera.center.astype(np.float32)),
        "u_intrinsics": (camera.fx, camera.fy, camera.cx, camera.cy),
        "u_viewport": (float(camera.width), float(camera.height)),
        "u_tan_fov": (tx, ty),
        "u_near": float(near_threshold(near, np.float32)),
        **camera.model.uniforms(camera),
    }
    for name, value in values.items():
        if name in prog:
            prog[name].value = value


def _valid_elapsed(ns: int) -> int | None:
    """A timer query's nanoseconds, or None where the driver returns no real value (llvmpipe
    answers 2^32 - 1)."""
    return int(ns) if 0 < ns < 0xFFFFFFFF else None


class QuadRenderer:
    """Renders one scene through the quad path; reuse it across views, then :meth:`release`."""

    def __init__(self, ctx: moderngl.Context, scene: Scene, settings: RenderSettings,
                 programs: ProgramCache | None = None):
        self.ctx = ctx
        self.scene = scene
        self.settings = settings
        # The compute pre-pass covers 3DGS; surfels always take their vertex stage.
        self.uses_prepass = (settings.preprocess is Preprocess.COMPUTE
                             and scene.kind is SplatKind.GAUSSIAN_3D)
        self.programs = programs or ProgramCache(ctx)
        self.near = resolve_near(settings, scene.robust_radius)
        self.buffers = SceneBuffers(ctx, scene, settings.gpu_storage)
        self._chunks: ChunkedCull | None = None  # built on the first culled view
        self._cull_data: CullData | None = None  # the LOD renderer's (its cut's rows)
        self._sorter: RadixSorter | None = None  # built on the first device sort
        self._index_buffer: moderngl.Buffer | None = None
        self._prepared: moderngl.Buffer | None = None
        self._target: ColorTarget | None = None
        self._order_key: tuple | None = None
        self._order = np.zeros(0, np.uint32)
        self._stale_frames = 0
        self._count_fragments: str | None = None  # "shaded" / "rasterised" while counting
        #: Time the draw with a GL timer query too (the benchmark); result in last_gpu_draw_ns.
        self.gpu_timer = False
        #: Told the splats drawn after each batch (set per frame by ``Renderer.render(...,
        #: progress=...)``, :mod:`splatgl.progress`); Ctrl-C is seen between batches.
        self.progress = None
        self.last_gpu_draw_ns: int | None = None
        self._query: moderngl.Query | None = None
        self._stop = (EarlyStopPasses(ctx, self.programs)
                      if settings.early_stop is not EarlyStop.OFF else None)
        #: Whether the current frame draws in early-termination batches (decided per frame,
        #: :meth:`_decide_batches`), its coverage estimate, and the batches it drew.
        self._batched = settings.early_stop is EarlyStop.ON
        self._fragments_estimate = 0
        self._batches = 1
        self._schedule = COARSE_SCHEDULE  # the batch schedule of a batched frame
        self._vaos: dict[tuple, moderngl.VertexArray] = {}
        self._plain_command: moderngl.Buffer | None = None
        self._occlusion_culled = 0
        self._times_cull = self._times_sort = self._times_upload = self._times_build = 0.0
        self._times_prepass = self._times_draw = self._times_coverage = 0.0
        self.last_times: QuadTimes | None = None

    # --------------------------------------------------------------------------- stages
    def defines(self, camera: Camera, depth: bool = False) -> dict[str, object]:
        """The specialisation of the quad programs for this scene, settings and camera."""
        degree = self.scene.sh_degree if self.settings.sh_degree is None else min(
            self.settings.sh_degree, self.scene.sh_degree)
        defines: dict[str, object] = {
            "SH_DEGREE": degree,
            "SH_REST_COEFFS": self.buffers.sh_rest_coeffs,
        }
        if self.settings.extent is QuadExtent.SQUARE:
            defines["EXTENT_SQUARE"] = 1
        elif self.settings.extent is QuadExtent.FAST:
            defines["EXTENT_FAST"] = 1
        if self.settings.antialias:
            defines["ANTIALIAS"] = 1
        defines.update(camera.model.defines())
        if depth:
            defines["DEPTH_OUTPUT"] = 1
        if self._count_fragments is not None:
            defines["COUNT_FRAGMENTS"] = 1
            if self._count_fragments == "rasterised":
                defines["COUNT_RASTERISED"] = 1
        defines.update(self.buffers.defines())
        if self._batched:
            defines["EARLY_STOP"] = 1
            if self.uses_prepass:
                defines["SURVIVORS"] = 1
        return defines

    def _compute_defines(self, camera: Camera, depth: bool = False) -> dict[str, object]:
        """:meth:`defines` without the draw-only keys (early termination, fragment counting)."""
        return {k: v for k, v in self.defines(camera, depth).items()
                if k not in ("EARLY_STOP", "SURVIVORS", "COUNT_FRAGMENTS", "COUNT_RASTERISED")}

    def _rect_program(self, camera: Camera, name: str) -> moderngl.ComputeShader:
        """``name`` (occlusion_cull.comp, coverage.comp) in the variant that reads this path's
        splat rectangles (shaders/lib/splat_rect.glsl), camera uniforms set."""
        defines = self._compute_defines(camera)
        if self.uses_prepass:
            defines["PREPARED"] = 1
        elif self.scene.kind is SplatKind.SURFEL_2D:
            defines["SURFEL"] = 1
        comp = self.programs.compute(name, defines)
        set_camera_uniforms(comp, camera, self.near, self.scene.anchor)
        return comp

    def program(self, camera: Camera, depth: bool = False) -> moderngl.Program:
        """The draw program: full per-corner math, or the light one after the pre-pass.

        2DGS surfels use shaders/surfel.vert + surfel.frag (ray-splat intersection); the
        extent and antialiasing settings are 3DGS-only and do not change them.
        """
        camera.model.check_support(self.scene.kind is SplatKind.SURFEL_2D, "quad")
        if self.scene.kind is SplatKind.SURFEL_2D:
            return self.programs.program("surfel.vert", "surfel.frag", self.defines(camera, depth))
        vertex = "quad_light.vert" if self.uses_prepass else "quad.vert"
        return self.programs.program(vertex, "quad.frag", self.defines(camera, depth))

    def visible_order(self, camera: Camera) -> np.ndarray:
        """Cull and sort for ``camera``: (M,) uint32 splat indices, front to back.

        Re-sorted whenever the pose or intrinsics change (the same camera reuses the order);
        with ``resort_interval`` N > 1, only every N-th change re-sorts (sort lag).
        """
        key = (camera.world_to_camera.tobytes(), camera.fx, camera.fy, camera.cx, camera.cy,
               camera.width, camera.height, camera.model)
        self._times_cull = self._times_sort = self._times_build = 0.0
        if key == self._order_key:
            return self._order
        if self._order_key is not None and self._stale_frames + 1 < self.settings.resort_interval:
            self._stale_frames += 1
            self._order_key = key
            return self._order
        self._stale_frames = 0
        if (camera.is_lens or self.settings.cull) and self._chunks is None:
            tb = time.perf_counter()
            self._chunks = ChunkedCull.from_scene(self.scene)
            self._times_build = time.perf_counter() - tb
        t0 = time.perf_counter()
        anchored = anchored_camera(camera, self.scene.anchor)
        if camera.is_lens or self.settings.cull:
            if camera.is_lens:   # distance keys; equirect seam splats twice (splatgl/cameras/equirect.py)
                keys = lens_visible_keys(self._chunks, anchored, self.near, camera.scale)
            else:
                keys = self._chunks.visible_keys(anchored, self.near, self.settings.antialias,
                                                 camera.scale)
            t1 = time.perf_counter()
            if self.settings.sort_key is SortKey.EXACT:
                order = keys_order(keys)
            else:
                order = self.sort_visible(*keys_pairs(keys, self.scene.count))
        else:
            p_cam = to_camera(self.scene.relative_means, anchored)
            keep = np.flatnonzero(p_cam[:, 2] > self.near).astype(np.uint32)  # keys need z > 0
            depth = p_cam[keep, 2]
            t1 = time.perf_counter()
            order = self.sort_visible(depth, keep)
        t2 = time.perf_counter()
        self._times_cull, self._times_sort = t1 - t0, t2 - t1
        self._order_key, self._order = key, order
        return order

    @property
    def order_times(self) -> tuple[float, float]:
        """Seconds of the last :meth:`visible_order`'s ``(cull, sort)`` stages (0 when the
        order was reused)."""
        return self._times_cull, self._times_sort

    def sort_visible(self, depth: np.ndarray, keep: np.ndarray) -> np.ndarray:
        """The sort stage the settings choose: (M,) uint32 ``keep`` front to back by ``depth``."""
        if self.settings.sort_key is SortKey.GPU:
            self._sorter = self._sorter or RadixSorter(self.ctx, self.programs)
            return device_depth_sort(self._sorter, depth, keep)
        sort = bucket_sort if self.settings.sort_key is SortKey.BUCKET16 else depth_sort
        return sort(depth, keep)

    def _upload(self, order: np.ndarray, prog: moderngl.Program | None = None) -> None:
        """Write the sorted indices (the only per-view upload)."""
        data = order.tobytes()
        if self._index_buffer is None or self._index_buffer.size < max(len(data), 4):
            if self._index_buffer is not None:
                self._release_vaos()
                self._index_buffer.release()
            self._index_buffer = self.ctx.buffer(reserve=max(len(data), 4))
        if data:
            self._index_buffer.write(data)

    def _vertex_array(self, prog: moderngl.Program, source: moderngl.Buffer | None) -> moderngl.VertexArray:
        """The VAO drawing ``prog`` with its per-instance attribute read from ``source``: the
        sorted indices, the occlusion cull's survivors, or none (the pre-pass's instance k
        reads prepared[u_base + k])."""
        attribute = "splat_slot" if self.uses_prepass else "splat_index"
        key = (prog.glo, None if source is None else source.glo)
        vao = self._vaos.get(key)
        if vao is None:
            content = [] if source is None else [(source, "u4/i", attribute)]
            vao = self._vaos[key] = self.ctx.vertex_array(prog, content)
        return vao

    def _release_vaos(self) -> None:
        for vao in self._vaos.values():
            vao.release()
        self._vaos.clear()

    def _prepass(self, camera: Camera, count: int, depth: bool) -> None:
        """Run quad_prepass.comp over the ``count`` sorted splats into the prepared buffer."""
        need = max(count * PREPARED_BYTES, 16)
        if self._prepared is None or self._prepared.size < need:
            if self._prepared is not None:
                self._prepared.release()
            self._prepared = self.ctx.buffer(reserve=need)
        self._prepared.bind_to_storage_buffer(BINDING_PREPARED)
        if count == 0:
            return
        comp = self.programs.compute("quad_prepass.comp", self._compute_defines(camera, depth))
        set_camera_uniforms(comp, camera, self.near, self.scene.anchor)
        comp["u_count"].value = count
        self._index_buffer.bind_to_storage_buffer(BINDING_ORDER)
        comp.run(group_x=(count + PREPASS_GROUP - 1) // PREPASS_GROUP)
        self.ctx.memory_barrier()

    def target(self, camera: Camera, depth: bool = False) -> ColorTarget:
        size = (camera.width, camera.height)
        t = self._target
        stop = self._stop is not None
        if (t is None or t.size != size or t.precision is not self.settings.precision
                or t.has_depth != depth or t.has_stop_mask != stop):
            if t is not None:
                t.release()
            self._target = ColorTarget(self.ctx, camera.width, camera.height, self.settings.precision,
                                       depth, stop_mask=stop)
        return self._target

    def draw(self, camera: Camera, target: ColorTarget, depth: bool = False,
             on_batch: BatchHook | None = None) -> int:
        """Cull, sort, upload and draw into ``target`` (cleared to 0); returns splats drawn.

        With ``depth`` the program also writes the depth layer to the target's attachment 1
        (``target`` from :meth:`target`).  ``on_batch(done, total)`` is called after each batch
        of sorted splats; an exception it raises abandons the frame (GL state restored).
        """
        camera.model.check_support(self.scene.kind is SplatKind.SURFEL_2D, "quad")
        order = self.visible_order(camera)
        t0 = time.perf_counter()
        self._upload(order)
        t1 = time.perf_counter()
        self.buffers.bind()
        if self.uses_prepass:
            self._prepass(camera, len(order), depth)
            self.ctx.finish()
        tp = time.perf_counter()
        self._batched = self._decide_batches(camera, len(order))
        tc = time.perf_counter()
        prog = self.program(camera, depth)
        set_camera_uniforms(prog, camera, self.near, self.scene.anchor)
        fbo = target.fbo
        fbo.use()
        self.ctx.viewport = (0, 0, camera.width, camera.height)
        self.ctx.disable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        if target.has_stop_mask:
            fbo.depth_mask = True  # a clear writes depth only through the mask
        fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        self.ctx.blend_func = moderngl.ONE_MINUS_DST_ALPHA, moderngl.ONE
        self.ctx.blend_equation = moderngl.FUNC_ADD
        self._occlusion_culled = 0
        self._batches = 0
        try:
            if len(order):
                if self.gpu_timer:
                    if self._query is None:
                        self._query = self.ctx.query(time=True)
                    with self._query:
                        self._draw_batches(camera, target, prog, len(order), on_batch)
                    self.ctx.finish()
                    self.last_gpu_draw_ns = _valid_elapsed(self._query.elapsed)
                else:
                    self._draw_batches(camera, target, prog, len(order), on_batch)
        finally:
            self.ctx.disable(moderngl.BLEND | moderngl.DEPTH_TEST)
        self.ctx.finish()
        t2 = time.perf_counter()
        self._times_upload, self._times_prepass = t1 - t0, tp - t1
        self._times_coverage, self._times_draw = tc - tp, t2 - tc
        self._drawn = len(order)
        return len(order)

    def _decide_batches(self, camera: Camera, count: int) -> bool:
        """Whether this frame draws in early-termination batches, and their schedule.

        OFF: never.  ON and AUTO first estimate the fragments a plain draw would rasterise
        (coverage.comp; needs the order, scene and prepared quads bound).  ON always batches,
        AUTO from EARLY_STOP_MIN_QUAD_FRAGMENTS fragments per quad and EARLY_STOP_MIN_OVERDRAW
        per image pixel; both take the fine schedule from EARLY_STOP_FINE_QUAD_FRAGMENTS per
        quad, else the coarse one (constants.py)."""
        self._fragments_estimate = 0
        mode = self.settings.early_stop
        if mode is EarlyStop.OFF or count == 0:
            return False
        self._index_buffer.bind_to_storage_buffer(BINDING_ORDER)
        estimate = self._stop.coverage(self._rect_program(camera, "coverage.comp"), count)
        self._fragments_estimate = int(round(estimate))
        fine = estimate >= EARLY_STOP_FINE_QUAD_FRAGMENTS * count
        self._schedule = FINE_SCHEDULE if fine else COARSE_SCHEDULE
        if mode is EarlyStop.ON:
            return True
        return (estimate >= EARLY_STOP_MIN_QUAD_FRAGMENTS * count
                and estimate >= EARLY_STOP_MIN_OVERDRAW * camera.width * camera.height)

    @property
    def last_batched(self) -> bool:
        """Whether the last draw ran early termination's batches."""
        return self._batched

    @property
    def last_fragments_estimate(self) -> int:
        """The last AUTO frame's coverage estimate, fragments (0 when none was made)."""
        return self._fragments_estimate

    def _draw_batches(self, camera: Camera, target: ColorTarget, prog: moderngl.Program, count: int,
                      on_batch: BatchHook | None) -> None:
        if not self._batched:
            bounds = plain_bounds(count)
            self._batches = len(bounds) - 1
            for start, end in zip(bounds[:-1], bounds[1:]):
                self._draw_range(prog, start, end - start)
                if on_batch is not None:
                    self.ctx.finish()
                    on_batch(end, count)
            return
        # Early termination (splatgl/renderers/early_stop.py): mark, reduce to tiles, cull, draw survivors.
        stop, ctx = self._stop, self.ctx
        width, height = camera.width, camera.height
        bounds = batch_bounds(count, *self._schedule)
        self._batches = len(bounds) - 1
        n_cmd = stop.prepare(count, bounds, width, height)
        cull_prog = self._rect_program(camera, "occlusion_cull.comp")
        self._index_buffer.bind_to_storage_buffer(BINDING_ORDER)
        vao = self._vertex_array(prog, stop.survivors)
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
            vao.render_indirect(stop.commands, moderngl.TRIANGLE_STRIP, count=groups, first=first)
            first += groups
            if on_batch is not None:
                ctx.finish()
                on_batch(end, count)
        self._occlusion_culled = count - stop.survivor_count(n_cmd)

    def _draw_range(self, prog: moderngl.Program, start: int, n: int) -> None:
        """Draw sorted slots [start, start + n) without early termination."""
        self.ctx.enable(moderngl.BLEND)
        if self.uses_prepass:
            prog["u_base"].value = start
            self._vertex_array(prog, None).render(moderngl.TRIANGLE_STRIP, vertices=4, instances=n)
            return
        vao = self._vertex_array(prog, self._index_buffer)
        if start == 0:
            vao.render(moderngl.TRIANGLE_STRIP, vertices=4, instances=n)
            return
        # A later range: the instanced attribute starts at baseInstance (an indirect command).
        if self._plain_command is None:
            self._plain_command = self.ctx.buffer(reserve=COMMAND_BYTES)
        self._plain_command.write(np.array([4, n, 0, start, 0], np.uint32).tobytes())
        vao.render_indirect(self._plain_command, moderngl.TRIANGLE_STRIP, count=1)

    def render(self, camera: Camera, on_batch: BatchHook | None = None) -> np.ndarray:
        """(H, W, 4) float32: RGB = C + (1 - A) background, alpha = A; row 0 is the top."""
        return self.render_layers(camera, depth=False, on_batch=on_batch).rgba

    def render_layers(self, camera: Camera, depth: bool = True,
                      on_batch: BatchHook | None = None) -> RenderOutput:
        """Colour and (with ``depth``) the accumulated depth layer, from the same pass;
        ``on_batch`` as in :meth:`draw`; without one, :attr:`progress` hears each batch."""
        if on_batch is None and self.progress is not None:
            report = self.progress
            on_batch = lambda done, total: report(done, total, "quad: drawing splats")  # noqa: E731
        target = self.target(camera, depth)
        self.draw(camera, target, depth, on_batch)
        t0 = time.perf_counter()
        rgba = target.read()
        d = target.read_depth() if depth else np.zeros(rgba.shape[:2], np.float32)
        t1 = time.perf_counter()
        self.last_times = QuadTimes(self._times_cull, self._times_sort, self._times_upload,
                                    self._times_prepass, self._times_draw, t1 - t0, self._drawn,
                                    self._occlusion_culled, self._times_build,
                                    self._times_coverage, self._fragments_estimate, self._batches,
                                    self._batched)
        return RenderOutput(composite(rgba, self.settings.background), d)

    def prepare_geometry(self, camera: Camera) -> int:
        """Cull, sort, upload and run the compute pre-pass for ``camera`` (no draw); returns
        the number of sorted splats whose quads now sit in the prepared buffer (binding 6).

        Needs ``preprocess=COMPUTE``; the benchmark's limit row draws this geometry.
        """
        order = self.visible_order(camera)
        self._upload(order)
        self.buffers.bind()
        self._prepass(camera, len(order), False)
        self.ctx.finish()
        return len(order)

    def count_fragments(self, camera: Camera, rasterised: bool = False) -> tuple[int, int]:
        """Draw once with counting shaders: (fragments shaded, fragments with alpha >= 1/255).

        Their ratio is the quad extent's fragment efficiency (the benchmark reports it).  With
        ``rasterised`` the first figure counts every fragment rasterised: with early
        termination the depth test then runs after the counter, so the fragments it rejects
        are counted too (without it, rasterised and shaded are the same).
        Atomic counters slow the draw, so this is a separate, untimed pass.
        """
        counts = self.ctx.buffer(np.zeros(2, np.uint32).tobytes())
        counts.bind_to_storage_buffer(BINDING_FRAGMENT_COUNTS)
        self._count_fragments = "rasterised" if rasterised else "shaded"
        try:
            self.draw(camera, self.target(camera))
        finally:
            self._count_fragments = None
        shaded, kept = np.frombuffer(counts.read(), np.uint32)
        counts.release()
        return int(shaded), int(kept)

    @property
    def last_occlusion_culled(self) -> int:
        """Splats the occlusion cull dropped in the last draw (0 with early_stop off)."""
        return self._occlusion_culled

    def release(self) -> None:
        self._release_vaos()
        if self._stop is not None:
            self._stop.release()
        for obj in (self._index_buffer, self._prepared, self._target, self._plain_command):
            if obj is not None:
                obj.release()
        self._index_buffer = self._prepared = self._target = self._plain_command = None
        if self._sorter is not None:
            self._sorter.release()
            self._sorter = None
        self.buffers.release()
