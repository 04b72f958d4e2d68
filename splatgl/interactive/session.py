"""An interactive view: budgeted frames while the camera moves, refined to exact when it rests.

:class:`Session` is the window-free core of ``splatgl view`` (and of the interactive benchmark
and ``render --path --preview``): the caller hands it the camera every loop iteration; a camera
that differs from the last one is a moving frame, drawn at the :class:`~.budget.FrameBudget`'s
level; the same camera again is rest, and each call then draws the next step of the refinement
(:meth:`Session.plan`: full detail at the moving frame's scale where the exact frame would take
long, then the exact frame, the same pixels as ``splatgl render``).  A refinement step draws in
batches of about a twentieth of a budget's worth of splats and asks ``input_pending()`` between
them (and between chunks of the pre-pass): input abandons the step at once
(:class:`Interrupted`), so the window answers within about one budgeted frame however long the
exact frame takes.
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import Callable

import numpy as np

from ..api import Renderer
from ..cameras.camera import Camera
from ..gl.context import renderer_name
from ..gl.egl_devices import is_software_renderer
from ..scene.splats import Scene
from ..scene.settings import RendererKind, RenderSettings
from ..renderers.early_stop import MAX_BATCH
from .budget import EXACT, FrameBudget, Level
from .costs import SPLAT_UNIT
from .draft import DraftFrame, LevelRenderer
from .lod_cache import LodProvider

#: Frames a second the budget aims at by default on a software rasteriser, and on a GPU.
SOFTWARE_FPS = 10.0
GPU_FPS = 60.0

#: A refinement step polls for input after each batch of about this share of the budget: the
#: answer to input waits for at most that batch plus one moving frame.  The share is of the
#: frame's mean cost per splat, and on close views the front splats cost several times the
#: mean: at 0.15, donut's batches ran up to 90 ms (latency up to 174 ms); at 0.05 up to 30 ms
#: (latency up to 131 ms), for 1.25x the exact frame's time on donut and none on the 1M scene.
REFINE_BATCH_SHARE = 0.05
#: Smallest batch of a refinement step's draw (splats): one draw command of the early-stop
#: path (early_stop.SEGMENT); below it the finish between batches costs more than it buys.
MIN_REFINE_BATCH = 1024
#: The calibration cut is drawn at this render scale, where the quality model's scale error is
#: nil, so the PSNR measured is the cut's alone.  Measured at the moving frame's scale it said
#: nothing where that scale was low: on an AVX2 llvmpipe donut moved at 0.15, where the model
#: put the scale's error above its 12k cut's, so the cut factor stayed 1 and the flight kept
#: cuts that lose 2.6 times the model's error.  At 0.5 guitar's cut (37.9 dB) still hid under
#: the scale's error.  The draw is one more at rest, after the exact frame, interrupted by input
#: like a refinement step.
CALIBRATION_SCALE = 1.0
#: A window spends time on each frame besides the draw (the viewer on an AVX2 llvmpipe: 7 ms to
#: present the frame, 5 ms to swap, about 5 ms more in its loop), so a draw that fills the whole
#: period misses the frame rate (donut at 10 fps: 7.9 fps in the window).  The draw's budget is
#: the period less the median of the last OVERHEAD_FRAMES moving frames' overhead
#: (:meth:`Session.note_overhead`): a median, so one slow swap does not move the levels.
OVERHEAD_FRAMES = 9
#: ... once at least this many have been measured: a window's first frames carry one-off costs
#: (the present program's compile, the status panel's font), and a median of one or two would
#: take them for the window's own cost.
OVERHEAD_MIN_FRAMES = 3
#: ... but never below this share of the period: an overhead that large is the window's problem,
#: and a draw squeezed further would only show worse frames at no better rate.
MIN_DRAW_SHARE = 0.5


def default_fps(renderer: Renderer) -> float:
    """:data:`SOFTWARE_FPS` where ``renderer``'s GL renderer is a software rasteriser (llvmpipe),
    else :data:`GPU_FPS`."""
    return SOFTWARE_FPS if is_software_renderer(renderer_name(renderer.ctx)) else GPU_FPS


class Interrupted(Exception):
    """Input arrived while a refinement step was drawing; the step was abandoned."""


def _interrupt_on(input_pending: Callable[[], bool]):
    """A batch hook that abandons the draw (:class:`Interrupted`) once ``input_pending()``."""
    def hook(done: int, total: int) -> None:
        if input_pending():
            raise Interrupted
    return hook


def camera_key(camera: Camera) -> tuple:
    return (camera.world_to_camera.tobytes(), camera.fx, camera.fy, camera.cx, camera.cy,
            camera.width, camera.height, camera.model)


class Session:
    """Frames of one scene for one window (see the module doc).

    ``budget``: seconds a moving frame may take (the frame period; the draw's share of it
    follows :meth:`note_overhead`); ``lod``: the level-of-detail provider (None: no splat
    budgets); ``exact_kind``: the renderer of the exact frame at rest, the quad path or the CPU
    renderer (``RendererKind.CPU``: moving frames are the quad path's drafts as ever, and the
    rest refines straight to the CPU renderer's exact frame, drawn in bands that input
    interrupts; its cost stays out of the budget's model, which prices quad frames); ``levels``:
    what draws them (a streamed scene's: :func:`~.stream_levels.streamed_session`).  After
    each :meth:`frame`: :attr:`shown` (the frame to present), :attr:`status` ("moving",
    "refining" or "exact").
    """

    def __init__(self, renderer: Renderer, scene: Scene, settings: RenderSettings, budget: float,
                 lod: LodProvider | None = None,
                 exact_kind: RendererKind | str = RendererKind.QUAD,
                 levels: LevelRenderer | None = None):
        self.renderer, self.scene, self.settings = renderer, scene, settings
        self.cpu_exact = RendererKind(exact_kind) is RendererKind.CPU
        self.lod = lod
        self.levels = levels or LevelRenderer(renderer, scene, settings, lod)
        self._whole, self._whole_generation = True, None   # see _note_whole
        software = is_software_renderer(renderer_name(renderer.ctx))   # the cost model's prior
        self.budget = FrameBudget(budget, scene.count, 1280 * 720, scene.sh_degree, has_lod=False,
                                  software=software)
        self.period = self.budget.budget
        self._overheads: list[float] = []
        #: Whether the last frame drawn was a moving frame (not a refinement step).
        self.moved = False
        self.shown: DraftFrame | None = None
        self.status = "exact"
        self._key: tuple | None = None
        self._moving_level: Level = EXACT
        self._plan: list[Level] = []
        self.refine_started: float | None = None
        self._full_per_splat: float | None = None   # seconds a splat of the last full-detail step
        self._calibration: Level | None = None      # the cut to measure at rest, after exact
        self._quad_cost = False     # at rest after the CPU frame: time the quad path's exact one
        #: (level, PSNR against the exact frame) of each calibration so far.
        self.calibrations: list[tuple[Level, float]] = []
        #: log(triangle seconds / quad seconds) of the calibration level at each rest so far.
        self.primitive_log: list[float] = []

    def _sync_lod(self) -> None:
        if self.levels.has_lod and not self._lod_seen:
            self.budget.set_lod(True)
            self._lod_seen = True

    _lod_seen = False

    def plan(self, moving: Level) -> list[Level]:
        """The refinement steps after a moving frame at ``moving``: full detail at its scale
        first where the exact frame is predicted to take over two budgets, then exact."""
        steps = []
        if self.cpu_exact:          # a few budgets at most, and interruptible: no middle step
            return [EXACT]
        if not moving.exact and self.budget.predict(EXACT) > 2.0 * self.budget.budget:
            step = Level(moving.scale)
            if step != moving and not step.exact:
                steps.append(step)
        steps.append(EXACT)
        return steps

    def _batch(self) -> int:
        """Splats per batch of a refinement step: about REFINE_BATCH_SHARE of a budget's worth,
        at the last full-detail frame's cost per splat (else the cost model's)."""
        per_splat = self._full_per_splat or self.budget.model.theta[1] / SPLAT_UNIT
        if per_splat <= 0.0:
            return MAX_BATCH
        return int(min(MAX_BATCH, max(MIN_REFINE_BATCH,
                                      REFINE_BATCH_SHARE * self.budget.budget / per_splat)))

    def frame(self, camera: Camera, input_pending: Callable[[], bool] | None = None) -> DraftFrame | None:
        """Draw what ``camera`` calls for now (a moving frame or the next refinement step);
        returns the new frame, or None when there is nothing new (exact already) or a
        refinement step was interrupted (:attr:`shown` stays the last frame)."""
        self._sync_lod()
        self.budget.set_pixels(camera.width * camera.height)
        key = camera_key(camera)
        if key != self._key:
            return self.moving(camera)
        hook = None if input_pending is None else _interrupt_on(input_pending)
        if self.awaiting:   # a streamed exact frame short of chunks: again once one arrives
            self.status = "refining"
            if self.levels.generation == self._whole_generation:
                return None
            self._plan = [EXACT]
        if not self._plan:
            if self._quad_cost:
                self._observe_quad_exact(camera, hook)
            elif self._calibration is not None:
                self._calibrate(camera, hook)
            self.status = "exact"
            return None
        if self.refine_started is None:
            self.refine_started = time.perf_counter()
        level = self._plan[0]
        on_cpu = level.exact and self.cpu_exact
        try:
            frame = (self.levels.draw_cpu(camera, on_batch=hook) if on_cpu else
                     self.levels.draw(camera, level, on_batch=hook, max_batch=self._batch()))
        except Interrupted:
            self.status = "refining"
            return None
        self._plan.pop(0)
        self.moved = False
        if level.budget is None and frame.splats and not on_cpu:
            self._full_per_splat = frame.seconds / frame.splats
        if level.exact:
            if not on_cpu:
                self.budget.observe(level, frame.splats, frame.seconds)
            self._quad_cost = on_cpu
            self._calibration = self._calibration_level()
        self.shown = frame
        self._note_whole(level)
        self.status = "refining" if self._plan or not self._whole else "exact"
        return frame

    def _note_whole(self, level: Level) -> None:   # final: not the exact level short of chunks
        self._whole, self._whole_generation = not level.exact or self.levels.complete, self.levels.drawn_generation

    def moving(self, camera: Camera) -> DraftFrame:
        """Draw ``camera`` as a moving frame (at the budget's level) whatever the last camera
        was; refinement starts over from it."""
        self._sync_lod()
        self.budget.set_pixels(camera.width * camera.height)
        if self.status != "moving":
            self.budget.resume()
        level = self.budget.level()
        frame = self.levels.draw(camera, level)
        self.budget.report(level, frame.splats, frame.seconds)
        self._key, self.shown, self._moving_level = camera_key(camera), frame, level
        self.moved = True
        self._note_whole(level)
        final = level.exact and not self.cpu_exact   # the CPU renderer's exact frame is its own
        self._plan = [] if final else self.plan(level)
        self._calibration = None                  # it was for the camera at rest
        self._quad_cost = False
        self.status = "exact" if final and self._whole else "moving"
        self.refine_started = None
        return frame

    def redraw(self) -> None:
        """Draw the next frame anew whatever the camera (the window showed something else in
        between: another view, another renderer): a moving frame, then refinement."""
        self._key = None

    def note_overhead(self, seconds: float) -> None:
        """The caller spent ``seconds`` on the last moving frame besides its draw (the viewer:
        presenting it, swapping, its loop).  The draw's budget becomes the frame period less
        the median of the last :data:`OVERHEAD_FRAMES` of these (from the
        :data:`OVERHEAD_MIN_FRAMES`-th on), and at least
        :data:`MIN_DRAW_SHARE` of the period, so whole frames land within the period."""
        if not (math.isfinite(seconds) and seconds >= 0.0):
            return
        self._overheads = (self._overheads + [float(seconds)])[-OVERHEAD_FRAMES:]
        if len(self._overheads) < OVERHEAD_MIN_FRAMES:
            return
        overhead = float(np.median(self._overheads))
        self.budget.set_budget(max(MIN_DRAW_SHARE * self.period, self.period - overhead))

    def _calibration_level(self) -> Level | None:
        """The cut to measure against the exact frame just drawn: the last moving frame's level,
        else the one the budget would move at (None without a cut)."""
        if not self.levels.has_lod:
            return None
        for level in (self._moving_level, self.budget.levels[self.budget.target()]):
            if level.budget is not None:
                return level
        return None

    def _calibrate(self, camera: Camera, hook) -> None:
        """At rest, after the exact frame: draw the calibration cut for the same camera (at
        :data:`CALIBRATION_SCALE`, so the cut's error is what is measured) and tell the
        budget its PSNR (:meth:`~.budget.FrameBudget.calibrate`), so the levels are ranked by
        what cuts cost in this scene.  Input abandons it like a refinement step."""
        level, self._calibration = self._calibration, None
        measured_at = dataclasses.replace(level, scale=CALIBRATION_SCALE)
        exact = self.levels.read(self.shown)   # still the exact frame (a cut draws elsewhere)
        try:
            draft = self.levels.draw(camera, measured_at, on_batch=hook, max_batch=self._batch())
        except Interrupted:
            return
        got = self.levels.read(draft)
        mse = float(np.mean((got[..., :3].astype(np.float64) - exact[..., :3]) ** 2))
        measured = math.inf if mse == 0.0 else -10.0 * math.log10(mse)
        self.calibrations.append((measured_at, measured))
        self.budget.calibrate(measured_at, measured)
        if measured_at != level:        # the primitives are timed at the moving frame's level,
            try:                        # after a draw of it (neither pays for a cold order)
                self.levels.draw(camera, level, on_batch=hook, max_batch=self._batch())
            except Interrupted:
                return
        self._choose_primitive(camera, level, hook)

    def _choose_primitive(self, camera: Camera, level: Level, hook) -> None:
        """Time ``level`` (the moving frame's level, just drawn) once more with each primitive
        for the camera at rest, and keep for drafts the one faster on average over the rests so
        far.  One triangle a splat saves a vertex at a third more fragments: it pays where
        llvmpipe's per-splat front end dominates (biker, guitar: 0.79-0.95x), not on fill-bound
        close views (donut: up to 1.16x).  Both are timed after a draw of the same view, so neither
        pays for a cold cache; input abandons the timing like a refinement step."""
        levels, current = self.levels, self.levels.triangles
        seconds = {}
        try:
            for triangles in (not current, current):
                levels.triangles = triangles
                seconds[triangles] = levels.draw(camera, level, on_batch=hook,
                                                 max_batch=self._batch()).seconds
        except Interrupted:
            return
        finally:
            levels.triangles = current
        self.primitive_log.append(math.log(seconds[True] / seconds[False]))
        levels.triangles = sum(self.primitive_log) < 0.0

    def _observe_quad_exact(self, camera: Camera, hook) -> None:
        """At rest, after the CPU renderer's exact frame is shown: draw the quad path's exact
        frame unseen, so that the budget's model (which prices quad frames) and the refinement
        batches (sized by the last full-detail quad frame's cost per splat) learn from it as
        they do when the quad path draws the exact frame.  Without it the model saw drafts
        only, and the batches were sized from its estimate (the 1M scene's input latency
        reached 171 ms).  Input abandons it like a refinement step."""
        try:
            frame = self.levels.draw(camera, EXACT, on_batch=hook, max_batch=self._batch())
        except Interrupted:
            return
        self._quad_cost = False
        self.budget.observe(EXACT, frame.splats, frame.seconds)
        if frame.splats:
            self._full_per_splat = frame.seconds / frame.splats

    @property
    def pending(self) -> bool:
        """Whether calls at rest still have work: refinement steps, the quad path's exact cost
        (after the CPU renderer's frame), or the calibration."""
        return bool(self._plan) or self._quad_cost or self._calibration is not None

    @property
    def awaiting(self) -> bool:
        """Whether the frame at rest only waits for streamed chunks (the viewer may sleep)."""
        return not self._plan and not self._whole

    @property
    def exact(self) -> bool:
        return self.status == "exact" and self._whole and self.shown is not None and self.shown.level.exact

    def release(self) -> None:
        self.levels.release()
