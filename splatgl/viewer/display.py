"""What the viewer's window shows: the rendered frame and the status panel over it.

:class:`Display` owns the :class:`~splatgl.api.Renderer` on the window's context (the one
``splatgl render`` uses), the :class:`~.present.Presenter` that samples frames onto the window
and the :class:`~.overlay.Overlay`; it keeps the last frame and the recent frame times the panel
reports.  When to render, present and swap is the viewer's business (:mod:`.app`).
"""

from __future__ import annotations

import moderngl
import numpy as np

from ..api import Renderer
from ..cameras.camera import Camera
from ..scene.splats import Scene
from ..scene.settings import RendererKind, RenderSettings
from .modes import FrameResult, ViewMode, render_frame, render_stereo
from .overlay import COMPACT_WINDOW, Message, Overlay, Status, status_lines
from .present import Mode, Presenter, fit_viewport

#: Frame times the status panel's mean covers.
FRAME_TIMES = 20
#: The Ctrl+click marker: half its size (pixels) and its colour (RGB).
MARKER_RADIUS = 7
MARKER_RGB = (1.0, 0.0, 1.0)


def lens_fov(camera: Camera, fov_y: float) -> str:
    """The field of view the status panel names for ``camera``: a fisheye's image circle, a
    panorama's whole sphere, else the vertical field of view ``fov_y`` (degrees)."""
    name = getattr(camera.model, "name", "perspective")
    if name == "fisheye":
        from ..cameras.fisheye import fisheye_theta_d

        edge = 0.5 * min(camera.width, camera.height) / camera.fy   # the image circle's edge
        grid = np.linspace(0.0, 2.0 * np.pi, 36001)
        reach = np.flatnonzero(fisheye_theta_d(grid, camera.model.k) >= edge)
        theta = grid[reach[0]] if reach.size else np.pi
        return f"fov {2.0 * np.degrees(theta):.1f} fisheye"
    if name == "equirectangular":
        return "fov 360x180 panorama"
    if name == "orthographic":
        return "orthographic"
    return f"fov {fov_y:.1f}"


def marker_image(radius: int = MARKER_RADIUS) -> np.ndarray:
    """(2r+1, 2r+1, 4) straight-alpha cross hair of :data:`MARKER_RGB` with a dark outline,
    open in the middle (the pixel listed stays visible)."""
    n = 2 * radius + 1
    img = np.zeros((n, n, 4), np.float32)
    for lo, hi, rgb in ((radius - 1, radius + 2, (0.0, 0.0, 0.0)), (radius, radius + 1, MARKER_RGB)):
        for arm in (slice(0, radius - 1), slice(radius + 2, n)):
            img[arm, lo:hi, :3] = rgb
            img[arm, lo:hi, 3] = 1.0
            img[lo:hi, arm, :3] = rgb
            img[lo:hi, arm, 3] = 1.0
    return img


class Display:
    """The renderer, presenter and overlay of one window's context ``ctx``."""

    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        self.renderer = Renderer(ctx)
        self.presenter = Presenter(ctx)
        self.overlay = Overlay()
        self.last: FrameResult | None = None
        self.frame_times: list[float] = []    # whole frames drawn in full (no budget)
        self.moving_times: list[float] = []   # a budget's moving frames
        #: (whole, sort, draw) seconds of the last frame drawn in full (with a budget: exact).
        self.exact: tuple[float, float, float] | None = None
        self.message = Message()
        #: The Ctrl+click marker: (image pixel, what it was picked in) or None.
        self.marker: tuple[tuple[int, int], tuple] | None = None

    def new_renderer(self) -> None:
        """Release the renderer's GPU state (paths and programs; the context is the window's)
        and start a fresh one, e.g. for new settings (one scene copy at a time)."""
        self.renderer.close()
        self.renderer = Renderer(self.ctx)

    def render(self, scene: Scene, camera: Camera, settings: RenderSettings, kind: RendererKind,
               view: ViewMode, stereo: float | None = None) -> FrameResult:
        """One frame of ``camera`` (kept as :attr:`last`): :func:`render_frame`, or with
        ``stereo`` (an IPD; colour view only) both eyes side by side (:func:`render_stereo`)."""
        if stereo is None or view is not ViewMode.COLOR:
            self.last = render_frame(self.renderer, scene, camera, settings, kind, view)
        else:
            self.last = render_stereo(self.renderer, scene, camera, settings, kind, stereo)
        return self.last

    def show(self, frame: FrameResult) -> FrameResult:
        """Keep ``frame`` (a budgeted frame, already at the camera's size: :mod:`.pacing`) as
        :attr:`last`."""
        self.last = frame
        return frame

    def record_frame_time(self, seconds: float, moving: bool = False, exact: bool = True) -> None:
        """The last frame's whole time (render and present), for the panel: a ``moving`` frame
        of a budget counts in the moving rate; an ``exact`` one (every frame without a budget)
        becomes the exact frame's cost (with its sort and draw) and counts in the plain rate."""
        if moving:
            self.moving_times = (self.moving_times + [seconds])[-FRAME_TIMES:]
        if exact and self.last is not None:
            self.exact = (seconds, self.last.sort, self.last.draw)
            if not moving:
                self.frame_times = (self.frame_times + [seconds])[-FRAME_TIMES:]

    def draw(self, size: tuple[int, int], background, shown: tuple = ()) -> None:
        """Draw the last frame (fitted, centred), the Ctrl+click marker where it was picked in
        ``shown`` (the view now) and the overlay into the window's framebuffer of ``size``
        (w, h) pixels over ``background`` (RGB); the caller swaps."""
        fbo = self.ctx.screen
        fbo.use()
        w, h = size
        self.ctx.viewport = (0, 0, w, h)
        fbo.clear(*background, 1.0)
        if self.last is not None:
            mode = Mode.PREMULTIPLIED if self.last.premultiplied else Mode.OPAQUE
            tex = self.last.texture if self.last.texture is not None else \
                self.presenter.upload("frame", self.last.image)
            viewport = fit_viewport(tex.size, (w, h))
            self.presenter.draw(tex, mode, viewport, background)
            if self.marker is not None and self.marker[1] == shown:
                self._draw_marker(self.marker[0], tex.size, viewport)
        if self.overlay.image is not None and (self.overlay.visible or not self.overlay.full):
            img = self.overlay.image
            oh, ow = img.shape[:2]
            tex = self.presenter.upload("overlay", img)
            self.presenter.draw(tex, Mode.OVERLAY, (8, h - 8 - oh, ow, oh))

    def _draw_marker(self, pixel: tuple[int, int], image_size, viewport) -> None:
        x0, y0, vw, vh = viewport
        cx = x0 + (pixel[0] + 0.5) * vw / image_size[0]
        cy = y0 + vh - (pixel[1] + 0.5) * vh / image_size[1]     # GL rows count from the bottom
        n = 2 * MARKER_RADIUS + 1
        tex = self.presenter.upload("marker", marker_image())
        self.presenter.draw(tex, Mode.OVERLAY, (int(cx) - MARKER_RADIUS, int(cy) - MARKER_RADIUS, n, n))

    def panel(self, status: Status, size: tuple[int, int], now: float, force: bool) -> bool:
        """Hand the overlay its lines for ``status`` in a window of ``size``: the whole panel
        (compact in a small window), or with the panel hidden the message alone.  Returns
        whether the overlay's image changed."""
        compact = size[0] < COMPACT_WINDOW[0] or size[1] < COMPACT_WINDOW[1]
        if self.overlay.visible:
            return self.overlay.update(status_lines(status, compact), now, force, compact)
        lines = [status.message] if status.message else []
        return self.overlay.update(lines, now, force, compact, full=False)

    def status(self, scene: Scene, settings: RenderSettings, kind: RendererKind, view: ViewMode,
               camera: Camera, fov: str, camera_text: str, paced: bool) -> Status:
        """The status panel's contents for ``camera`` (the size shown) and the last frame;
        ``camera_text`` names the training camera; ``paced``: the frames go through a budget
        (the rate shown is the moving frames')."""
        last = self.last
        times = self.moving_times if paced else self.frame_times
        mean = float(np.mean(times)) if times else 0.0
        whole, sort, draw = self.exact if self.exact is not None else (0.0, 0.0, 0.0)
        s = settings
        sh = f"SH {min(s.sh_degree, scene.sh_degree) if s.sh_degree is not None else scene.sh_degree}" \
             f"/{scene.sh_degree}"
        bg = ",".join(f"{v:g}" for v in s.background)
        return Status(renderer=kind.value, fps=1.0 / mean if mean > 0 else 0.0, frame=whole,
                      sort=sort, draw=draw,
                      splats=last.splats if last else f"splats - / {scene.count:,}",
                      settings=f"{s.precision.value}  {sh}  {s.extent.value}  sort "
                               f"{s.sort_key.value}  bg {bg}"   # the sort --sort auto took
                               + ("  antialias" if s.antialias else ""),
                      size=(camera.width, camera.height), fov=fov,
                      view=view.value, camera=camera_text,
                      message="  ".join(m for m in (last.note if last else "",
                                                    self.message.current()) if m),
                      quality=(last.quality or "exact (as splatgl render)") if last else "",
                      moving=paced)

    def release(self) -> None:
        """Release the renderer's and presenter's GPU objects (not the context)."""
        self.renderer.close()
        self.presenter.release()

