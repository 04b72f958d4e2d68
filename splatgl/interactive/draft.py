"""Drawing one view at a :class:`~.budget.Level`: the render scale, a splat budget, an SH cap.

Full-detail levels draw with the scene's own quad renderer (the one :class:`splatgl.api.Renderer`
keeps for these settings, so the exact level is exactly ``splatgl render``'s image); budgeted
levels draw a level-of-detail cut of at most the budget's nodes through a second quad renderer
over the tree (:func:`splatgl.lod.source.lod_renderer`), with the SH degree capped.  A frame at
a lower render scale is drawn with the full-size frame's splat footprints (the screen-space
dilation scaled with the pixels: :func:`~splatgl.cameras.view.draft_low_pass`) and upscaled to
the camera's size at once (:mod:`.upscale`), so its time is the whole cost of the frame.  The image stays on the GPU (premultiplied ``(C, A)``); the viewer
samples it, a preview reads it back.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import moderngl
import numpy as np

from ..api import Renderer
from ..gl.transfers import TransferCounts, transfers
from ..cameras.camera import Camera
from ..cameras.view import View, draft_low_pass
from ..lod.selection import LodSettings
from ..lod.source import lod_renderer
from ..scene.splats import Scene
from ..scene.settings import EarlyStop, RendererKind, RenderSettings
from ..renderers.early_stop import MAX_BATCH, BatchHook
from ..renderers.quad import QuadRenderer, composite
from .budget import EXACT, Level
from .lod_cache import LodProvider
from .upscale import Upscaler

#: NumPy types of the target textures' moderngl dtypes (the precisions of gl/targets.py).
_READ_DTYPES = {"f4": np.float32, "f2": np.float16, "f1": np.uint8}

#: A budgeted cut is never finer than this (pixels): the budget, not the threshold, decides.
CUT_THRESHOLD_PX = 0.25

#: Bands of tile rows the CPU renderer's exact frame is blended in, input checked before each:
#: one per tile row at 720 rows (the 1M-splat scene's blend, about 0.45 s here, then yields
#: every 10 ms or so).
CPU_BANDS = 45

#: Drafts draw one triangle per splat instead of a quad (QuadRenderer.use_triangles): three
#: vertices instead of four where llvmpipe's per-primitive front end dominates, at a third more
#: fragments (measured: benchmarks/cheaper_splats.py, docs/interactive.md).
DRAFT_TRIANGLES = True


def scaled(camera: Camera, scale: float) -> Camera:
    """``camera`` at ``scale`` times its width and height (intrinsics scaled per axis)."""
    if scale == 1.0:
        return camera
    return camera.resized(max(1, round(camera.width * scale)), max(1, round(camera.height * scale)))


@dataclass
class DraftFrame:
    """One drawn view: ``texture`` holds it at the camera's size (premultiplied ``(C, A)``, row 0
    at the top; valid until the next draw), ``level`` what was drawn, ``size`` the pixels drawn
    (w, h: the camera's times the level's scale), ``splats`` how many, ``seconds`` how long the
    draw took (order stage, draw and upscale, to a finish), ``sort`` the order stage's share
    of it (cull and sort; the CPU renderer's projection and sort)."""

    level: Level
    texture: moderngl.Texture
    size: tuple[int, int]
    splats: int
    seconds: float
    sort: float = 0.0
    #: What the draw moved between host and device (:mod:`splatgl.gl.transfers`); None for
    #: the CPU renderer's frames (whose image is uploaded as a texture).
    transfers: TransferCounts | None = None
    #: The order stayed on the device (``--sort gpu``): ``splats`` is then the scene's count
    #: (every sorted slot), the drawn count is not read back.
    device_order: bool = False


class LevelRenderer:
    """Draws ``scene`` at any level on ``renderer``'s context (see the module doc)."""

    #: Whether the last draw had all it needed (always, in memory; a streamed scene's draws
    #: lack the chunks not yet resident: :mod:`.stream_levels`); a count of what has arrived
    #: (None: nothing arrives), now and when the last draw chose what to draw.
    complete: bool = True
    generation: int | None = None
    drawn_generation: int | None = None

    def __init__(self, renderer: Renderer, scene: Scene, settings: RenderSettings,
                 lod: LodProvider | None = None, triangles: bool = DRAFT_TRIANGLES):
        self.renderer, self.scene, self.settings, self.lod = renderer, scene, settings, lod
        self.triangles = triangles   # drafts (not the exact level) draw one triangle a splat
        self._lod_quad: QuadRenderer | None = None
        self._lod_sh: int | None = None
        self._upscaler: Upscaler | None = None
        self._cpu_texture: moderngl.Texture | None = None   # draw_cpu's frame

    @property
    def has_lod(self) -> bool:
        return self.lod is not None and self.lod.ready

    def _quad(self, level: Level) -> QuadRenderer:
        if level.budget is None and level.sh_degree is None:
            return self.renderer.renderer_for(self.scene, self.settings)
        if level.budget is None:   # full detail, SH capped: the API renderer keeps it
            return self.renderer.renderer_for(self.scene,
                                              dataclasses.replace(self.settings, sh_degree=level.sh_degree))
        tree = self.lod.tree
        if self._lod_quad is None or self._lod_sh != level.sh_degree:
            self._release_lod()
            settings = dataclasses.replace(self.settings, sh_degree=level.sh_degree,
                                           early_stop=EarlyStop.OFF)
            self._lod_quad = lod_renderer(self.renderer.ctx, tree, settings,
                                          LodSettings(CUT_THRESHOLD_PX, level.budget),
                                          self.renderer.programs)
            self._lod_sh = level.sh_degree
            self._lod_quad.rows.warm_start = True   # consecutive frames are near each other
        rows = self._lod_quad.rows
        if rows.lod.budget != level.budget:
            rows.lod = dataclasses.replace(rows.lod, budget=level.budget)
        return self._lod_quad

    def draw(self, camera: Camera, level: Level, on_batch: BatchHook | None = None,
             max_batch: int = MAX_BATCH) -> DraftFrame:
        """Draw ``camera`` (world frame, the window's size) at ``level``; ``on_batch(done,
        total)`` runs between batches of at most ``max_batch`` splats and may raise to abandon
        the frame (the image is the same whatever the batches)."""
        quad = self._quad(level)
        cam = scaled(camera, level.scale)
        view = dataclasses.replace(View.of(cam, quad.options, quad.scene),
                                   low_pass=draft_low_pass(camera, cam))
        t0 = time.perf_counter()
        before = transfers(self.renderer.ctx).snapshot()
        device = quad.device_order(view) is not None   # the order stays on the device
        order_times = None         # (the draw's own call reuses the order and times nothing)
        if on_batch is not None and not device:   # the CPU order stage comes first:
            count = len(quad.order(view))        # a chance to abandon the frame after it
            order_times = quad.rows.times
            on_batch(0, count)
        target = quad.target(view)
        batches, mode = quad.batches, quad.batches.mode
        batches.max_batch = max_batch
        if not level.exact:
            # Early termination's decision costs a coverage pass (8 ms at 1280x720 on llvmpipe)
            # and gained nothing there: drafts draw plainly.
            batches.mode = EarlyStop.OFF
            quad.use_triangles(self.triangles)
        try:
            drawn = quad.draw(view, target, on_batch=on_batch)
        finally:
            batches.max_batch, batches.mode = MAX_BATCH, mode
            quad.use_triangles(False)
        texture = target.texture
        if (cam.width, cam.height) != (camera.width, camera.height):
            if self._upscaler is None:
                self._upscaler = Upscaler(self.renderer.ctx)
            texture = self._upscaler.run(texture, (camera.width, camera.height))
            self.renderer.ctx.finish()
            transfers(self.renderer.ctx).sync()
        t = order_times or quad.rows.times
        moved = transfers(self.renderer.ctx).snapshot().since(before)
        if device:
            t, drawn = quad.order_times, quad.scene.count
        return DraftFrame(level, texture, (cam.width, cam.height), drawn, time.perf_counter() - t0,
                          t.cull + t.sort, moved, device)

    def draw_cpu(self, camera: Camera, on_batch: BatchHook | None = None) -> DraftFrame:
        """The exact frame of ``camera`` drawn by the CPU renderer (the one the API renderer
        keeps for these settings, so it is ``splatgl render --renderer cpu``'s image), in
        :data:`CPU_BANDS` bands with ``on_batch`` before each; held in a float texture
        (premultiplied ``(C, A)``) like the quad path's frames."""
        cpu = self.renderer.renderer_for(self.scene, self.settings, RendererKind.CPU)
        view = View.of(camera, self.settings, self.scene)
        t0 = time.perf_counter()
        rgba, _ = cpu.draw(view, on_batch=on_batch, bands=CPU_BANDS if on_batch else 1)
        size = (camera.width, camera.height)
        if self._cpu_texture is None or self._cpu_texture.size != size:
            if self._cpu_texture is not None:
                self._cpu_texture.release()
            self._cpu_texture = self.renderer.ctx.texture(size, 4, dtype="f4")
        self._cpu_texture.write(rgba)
        t = cpu.last_times
        return DraftFrame(EXACT, self._cpu_texture, size, t.drawn, time.perf_counter() - t0,
                          t.project + t.sort)

    def read(self, frame: DraftFrame) -> np.ndarray:
        """(H, W, 4) float32 of ``frame`` at the camera's size with the background composited
        (as ``render`` returns it)."""
        w, h = frame.texture.size
        raw = np.frombuffer(frame.texture.read(), dtype=_READ_DTYPES[frame.texture.dtype])
        rgba = raw.reshape(h, w, 4).astype(np.float32)
        if frame.texture.dtype == "f1":
            rgba /= 255.0
        return composite(rgba, self.settings.background)

    def _release_lod(self) -> None:
        if self._lod_quad is not None:
            self._lod_quad.release()
            self._lod_quad = None

    def release(self) -> None:
        self._release_lod()
        if self._cpu_texture is not None:
            self._cpu_texture.release()
            self._cpu_texture = None
        if self._upscaler is not None:
            self._upscaler.release()
            self._upscaler = None
