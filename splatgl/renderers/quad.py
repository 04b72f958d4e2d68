"""The graphics-API quad path (DESIGN.md section 3): order -> instanced quads -> blend.

Per view, a source of rows (:class:`~splatgl.order.stage.RowSource`: the plain scene's cull and
sort, or a level-of-detail cut, :class:`splatgl.lod.source.LodOrder`) gives the splats to draw,
front to back; only those indices are uploaded (the scene's storage buffers are uploaded once).
With ``--sort gpu`` (every camera model but omni-directional stereo) the order never leaves the device
(:mod:`~splatgl.renderers.quad_device`: cull, keys, compaction and sort in compute shaders, the
draw count and order read by an indirect draw); :attr:`QuadTimes.transfers` counts what a frame
moved between host and device (:mod:`splatgl.gl.transfers`).
The vertex stage (shaders/quad.vert) evaluates SH colour and the 2D covariance and sizes the
quad, or a compute pre-pass does that once per splat (shaders/quad_prepass.comp) and a light
vertex stage places the corners; the fragment stage (shaders/quad.frag) evaluates the conic
opacity.  Blending is front to back, (ONE_MINUS_DST_ALPHA, ONE), into a cleared (0, 0, 0, 0)
target.  The draw runs in batches (:mod:`splatgl.renderers.batches`): plain ones, or early
termination's, which stop shading pixels that are already opaque; a draw calls
``on_batch(done, total)`` between batches, which may raise KeyboardInterrupt to abandon the
frame.

The pieces: :mod:`~splatgl.renderers.quad_programs` (which shaders, which switches),
:mod:`~splatgl.renderers.quad_gpu` (buffers, vertex arrays, target),
:mod:`~splatgl.renderers.batches` (the batched draw); benchmark probes (fragment counters, GPU
timers) reach the draw through :attr:`QuadRenderer.frame_extra` and :attr:`QuadRenderer.around_draw`
(:mod:`splatgl.measure.bench.probes`).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import Callable

import moderngl
import numpy as np

from ..cameras.view import View
from ..gl.radix_sort import RadixSorter, device_depth_sort
from ..gl.scene_buffers import SceneBuffers
from ..gl.shaders import ProgramCache
from ..gl.transfers import TransferCounts, transfers
from ..gl.targets import ColorTarget
from ..scene.splats import Scene
from ..scene.settings import EarlyStop, QuadExtent, RenderSettings, RendererKind, SortKey
from ..order.stage import OrderTimes, RowSource, SceneOrder, cpu_sort
from ..output.layers import BASE, ORDERED, Layer, RenderOutput
from ..output.under import UnderLayer
from .batches import Batches
from .options import QuadOptions
from . import early_stop_device
from .early_stop import BatchHook
from .quad_device import DeviceOrder
from .quad_gpu import QuadResources
from .quad_layers import (check_ordered, composite, draw_ordered,  # noqa: F401 (composite: API)
                          layer_output, normal_location)
from .quad_programs import FrameSwitches, QuadPrograms
from .registry import Registered, check


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
    #: Splats the early-termination occlusion cull dropped (0 with early_stop off, and with the
    #: device order, whose early termination is decided on the device: ``batched`` is then
    #: True, ``batches`` the batches issued and ``fragments_estimate`` 0).
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
    #: The frame's transfers (:mod:`splatgl.gl.transfers`), apart from the one-time scene upload.
    transfers: TransferCounts = TransferCounts()
    #: Whether the order stayed on the device (``--sort gpu``, :mod:`.quad_device`); ``drawn``
    #: is then -1: the count lives in the draw command and is not read back.
    device_order: bool = False

    @property
    def total(self) -> float:
        return (self.cull_build + self.cull + self.sort + self.upload + self.prepass + self.coverage
                + self.draw + self.readback)

    @property
    def ordering(self) -> float:
        return self.cull + self.sort

    @property
    def drawing(self) -> float:
        return self.upload + self.draw

    def summary(self, count: int) -> str:
        if self.drawn < 0:
            return f"splats counted on the device / {count:,}"
        return f"splats {self.drawn:,} drawn / {count:,}"


class QuadRenderer(Registered):
    """Renders one scene through the quad path; reuse it across views, then :meth:`release`.

    ``rows``: where the sorted rows come from (default: :class:`SceneOrder` of ``scene``);
    a level-of-detail cut passes its own source over the tree's nodes (``scene`` is then
    ``tree.nodes``).  After each frame :attr:`last_times` holds its :class:`QuadTimes`.
    """

    kind = RendererKind.QUAD

    def __init__(self, ctx: moderngl.Context, scene: Scene, options: QuadOptions | RenderSettings,
                 programs: ProgramCache | None = None, rows: RowSource | None = None):
        options = self.own(options)   # the inria rules only, no emulation, global order
        self.ctx = ctx
        self.scene = scene
        self.buffers = SceneBuffers(ctx, scene, options.gpu_storage)
        self.programs = QuadPrograms(scene, options, self.buffers, programs or ProgramCache(ctx))
        self.uses_prepass = self.programs.uses_prepass
        self.gpu = QuadResources(ctx, self.uses_prepass)
        self.batches = Batches(ctx, options.early_stop, self.gpu, self.programs)
        self._sorter: RadixSorter | None = None  # built on the first device sort
        self._device: DeviceOrder | None = None  # the device-resident order, on first use
        self._device_frame = False
        self._device_times = (0.0, 0.0)
        self.rows: RowSource = rows if rows is not None else SceneOrder(scene, options, self.sort)
        #: Told the splats drawn after each batch (set per frame by ``Renderer.render(...,
        #: progress=...)``, :mod:`splatgl.progress`); Ctrl-C is seen between batches.
        self.progress = None
        #: Extra shader switches of the next frames (a benchmark probe's fragment counters).
        self.frame_extra: dict[str, object] = {}
        #: Called as ``around_draw(draw)`` to run the batched draw (a probe's GPU timer).
        self.around_draw: Callable[[Callable[[], None]], None] | None = None
        self.last_times: QuadTimes | None = None
        #: The switches of the last frame's draw (the ordered pass draws with them).
        self.last_frame: FrameSwitches | None = None

    # ---------------------------------------------------------------------------- stages
    def sort(self, depth: np.ndarray, keep: np.ndarray) -> np.ndarray:
        """The sort stage the settings choose: (M,) uint32 ``keep`` front to back by ``depth``."""
        if self.options.sort_key is SortKey.GPU:
            self._sorter = self._sorter or RadixSorter(self.ctx, self.programs.cache)
            return device_depth_sort(self._sorter, depth, keep)
        return cpu_sort(self.options)(depth, keep)

    def device_order(self, view: View, layers: frozenset[Layer] = BASE) -> DeviceOrder | None:
        """The device-resident order (:mod:`.quad_device`) when it draws this frame: ``--sort
        gpu`` with the cull on, the plain scene's rows, a view it culls, no ordered layers."""
        if (self.options.sort_key is not SortKey.GPU or not self.options.cull
                or not isinstance(self.rows, SceneOrder) or self.scene.count == 0
                or layers & ORDERED or not DeviceOrder.covers(view)):
            return None
        if self._device is None:   # its own sorter: the CPU order's device sort reuses its buffers
            self._device = DeviceOrder(self.ctx, self.scene, self.programs.cache,
                                       RadixSorter(self.ctx, self.programs.cache))
        return self._device

    @property
    def order_times(self) -> OrderTimes:
        """The last frame's order stage times (the device order's, or :attr:`rows`')."""
        return OrderTimes(*self._device_times) if self._device_frame else self.rows.times

    def target(self, view: View, layers: frozenset[Layer] = BASE) -> ColorTarget:
        """The blend target for ``view`` with the attachments ``layers`` need."""
        return self.gpu.target(view.width, view.height, self.options.precision,
                               Layer.DEPTH in layers, self.options.early_stop is not EarlyStop.OFF,
                               Layer.NORMAL in layers)

    def use_triangles(self, on: bool) -> None:
        """From the next frame, draw one triangle per splat (``on``) or the 4-vertex quad (the
        default).  The triangle circumscribes the splat's ellipse (shaders/lib/quad_emit.glsl):
        a third more fragments for three vertices instead of four, which pays where llvmpipe's
        per-primitive front end dominates (small splats, drafts at a lower scale).  Its image is
        the quad's up to rounding (108-130 dB on the shared scenes), so the exact frame keeps the
        quad.  Frames drawn with triangles are never batched by early termination (its indirect
        commands draw strips).  Only the ellipse extent draws triangles: the square and fast
        extents shade their quads' corners beyond the ellipse, which the triangle cuts off."""
        on = on and self.options.extent is QuadExtent.ELLIPSE
        self.gpu.triangles = on
        if on:
            self.frame_extra["TRIANGLE_PER_SPLAT"] = 1
        else:
            self.frame_extra.pop("TRIANGLE_PER_SPLAT", None)

    def order(self, view: View) -> np.ndarray:
        """The rows this view draws, front to back (the order stage of :attr:`rows`)."""
        check(self.kind, scene=self.scene, model=view.model)
        return self.rows.order(view)

    def prepare(self, view: View, layers: frozenset[Layer] = BASE, under: bool = False,
                on_batch: BatchHook | None = None) -> tuple[int, FrameSwitches]:
        """Order, upload and (with the pre-pass) prepare the quads of ``view``; returns the
        splats to draw and the frame's switches (``under``: a geometry depth test).  The scene
        and the order stay bound.  ``on_batch(0, count)`` is called between chunks of the
        pre-pass as between batches of the draw (:meth:`draw`), so input can abandon it.
        With the device-resident order the count is the scene's (the pre-pass runs on every
        sorted slot; the draw takes the kept ones from its command)."""
        device = self.device_order(view, layers)
        self._device_frame = device is not None
        if device is not None:
            return self._prepare_device(device, view, layers, under)
        order = self.order(view)
        weights = self.rows.slot_weights
        frame = FrameSwitches(depth=Layer.DEPTH in layers, weights=weights is not None,
                              extra=tuple(self.frame_extra.items()),
                              normal=normal_location(layers), under=under,
                              ordered_rect=bool(layers & ORDERED) and not self.programs.surfels)
        t0 = time.perf_counter()
        self.gpu.upload(order, weights)
        self._t_upload = time.perf_counter() - t0
        self.buffers.bind()
        t1 = time.perf_counter()
        if self.uses_prepass:
            comp = self.programs.prepass(view, frame)
            view.set_uniforms(comp)
            between = None if on_batch is None else lambda: on_batch(0, len(order))  # noqa: E731
            self.gpu.run_prepass(comp, len(order), frame.weights, bool(frame.normal),
                                 frame.ordered_rect, self.batches.max_batch, between)
            self.ctx.finish()
            transfers(self.ctx).sync()
        self._t_prepass = time.perf_counter() - t1
        return len(order), frame

    def _prepare_device(self, device: DeviceOrder, view: View, layers: frozenset[Layer],
                        under: bool) -> tuple[int, FrameSwitches]:
        check(self.kind, scene=self.scene, model=view.model)
        frame = FrameSwitches(depth=Layer.DEPTH in layers, weights=False,
                              extra=tuple(self.frame_extra.items()),
                              normal=normal_location(layers), under=under)
        cull, sort = device.run(view, 3 if self.gpu.triangles else 4, self.options.antialias)
        self._device_times = (cull, sort)
        self._t_upload = 0.0
        self.buffers.bind()
        t1 = time.perf_counter()
        if self.uses_prepass:   # over the kept slots, the count read on the device
            comp = self.programs.prepass(view, dataclasses.replace(
                frame, extra=frame.extra + (("DEVICE_COUNT", 1),)))
            view.set_uniforms(comp)
            transfers(self.ctx).uniforms(comp)
            self.gpu.run_prepass(comp, device.slots, False, bool(frame.normal), False,
                                 order=device.values, dispatch=device.run_prepass)
        self._t_prepass = time.perf_counter() - t1
        return device.slots, frame

    def draw(self, view: View, target: ColorTarget, layers: frozenset[Layer] = BASE,
             on_batch: BatchHook | None = None, under: UnderLayer | None = None) -> int:
        """Order, upload and draw into ``target`` (cleared to 0); returns the splats drawn.

        With :attr:`Layer.DEPTH` (:attr:`Layer.NORMAL`) in ``layers`` the program also writes
        the depth (normal) layer to the target's further attachments (``target`` from
        :meth:`target`); with ``under``, fragments at or behind its depth are skipped.
        ``on_batch(done, total)`` is called after each batch of sorted splats; an exception it
        raises abandons the frame (GL state restored).  :attr:`last_frame` keeps the switches.
        """
        count, frame = self.prepare(view, layers, under is not None, on_batch)
        if under is not None:
            self.gpu.bind_under(under.depth)
        tp = time.perf_counter()
        device_stop = (self._device_frame and not self.gpu.triangles
                       and self.batches.mode is not EarlyStop.OFF)
        if device_stop:   # batched as the device decides (early_stop_device.py)
            batched = self.batches.batched = True
        elif self.gpu.triangles or self._device_frame:   # plain draws only (see use_triangles)
            batched = self.batches.batched = False
        else:
            batched = self.batches.decide(view, count, frame)
        frame = dataclasses.replace(frame, batched=batched)
        self.last_frame = frame
        tc = time.perf_counter()
        prog = self.programs.draw(view, frame)
        view.set_uniforms(prog)
        transfers(self.ctx).uniforms(prog)
        fbo = target.fbo
        fbo.use()
        self.ctx.viewport = (0, 0, view.width, view.height)
        self.ctx.disable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        if target.has_stop_mask:
            fbo.depth_mask = True  # a clear writes depth only through the mask
        fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        self.ctx.blend_func = moderngl.ONE_MINUS_DST_ALPHA, moderngl.ONE
        self.ctx.blend_equation = moderngl.FUNC_ADD
        self.batches.batches = 0
        self.batches.occlusion_culled = 0
        try:
            if device_stop:
                run = lambda: early_stop_device.draw(self.batches, view, target, prog,  # noqa: E731
                                                     frame, self._device, self.gpu)
            elif self._device_frame:
                run = lambda: self.gpu.draw_indirect(prog, self._device.values,  # noqa: E731
                                                     self._device.command)
            else:
                run = lambda: self.batches.draw(view, target, prog, count, frame, on_batch)  # noqa: E731
            if count:
                if self.around_draw is not None:
                    self.around_draw(run)
                else:
                    run()
        finally:
            self.ctx.disable(moderngl.BLEND | moderngl.DEPTH_TEST)
        self.ctx.finish()
        transfers(self.ctx).sync()
        self._t_coverage, self._t_draw = tc - tp, time.perf_counter() - tc
        self._drawn = -1 if self._device_frame else count
        return self._drawn

    def render(self, view: View, layers: frozenset[Layer] = BASE,
               under: UnderLayer | None = None, on_batch: BatchHook | None = None) -> RenderOutput:
        """The ``layers`` of ``view`` (colour and alpha always; depth and normal from the same
        pass, same weights; median depth, count and top contributor from an ordered pass,
        :mod:`~splatgl.renderers.quad_layers`), composited into ``under`` if given;
        ``on_batch`` as in :meth:`draw`; without one, :attr:`progress` hears each batch."""
        layers = frozenset(layers)
        check_ordered(self.ctx, layers)
        before = transfers(self.ctx).snapshot()
        if on_batch is None and self.progress is not None:
            report = self.progress
            on_batch = lambda done, total: report(done, total, "quad: drawing splats")  # noqa: E731
        target = self.target(view, layers)
        count = self.draw(view, target, layers, on_batch, under)
        ordered = (draw_ordered(self, view, self.last_frame, count, on_batch)
                   if layers & ORDERED else None)
        t0 = time.perf_counter()
        rgba = target.read()
        out = layer_output(target, rgba, layers, ordered, under, self.options.background)
        t1 = time.perf_counter()
        order, b = self.order_times, self.batches
        self.last_times = QuadTimes(order.cull, order.sort, self._t_upload, self._t_prepass,
                                    self._t_draw, t1 - t0, self._drawn, b.occlusion_culled,
                                    order.build, self._t_coverage, b.fragments_estimate,
                                    b.batches, b.batched,
                                    transfers(self.ctx).snapshot().since(before),
                                    self._device_frame)
        return out

    def release(self) -> None:
        self.batches.release()
        self.gpu.release()
        if self._device is not None:
            self._device.release()
            self._device = None
        if self._sorter is not None:
            self._sorter.release()
            self._sorter = None
        self.buffers.release()
        release = getattr(self.rows, "release", None)
        if release is not None:
            release()
