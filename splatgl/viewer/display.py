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
from ..model.scene import Scene
from ..model.settings import RendererKind, RenderSettings
from .frames import FrameResult, ViewMode, render_frame, render_stereo
from .overlay import Overlay, Status
from .present import Mode, Presenter, fit_viewport

#: Frame times the status panel's mean covers.
FRAME_TIMES = 20


class Display:
    """The renderer, presenter and overlay of one window's context ``ctx``."""

    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        self.renderer = Renderer(ctx)
        self.presenter = Presenter(ctx)
        self.overlay = Overlay()
        self.last: FrameResult | None = None
        self.frame_times: list[float] = []

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

    def record_frame_time(self, seconds: float) -> None:
        """A whole frame's time (render and present), for the panel's mean."""
        self.frame_times = (self.frame_times + [seconds])[-FRAME_TIMES:]

    def draw(self, size: tuple[int, int], background) -> None:
        """Draw the last frame (fitted, centred) and the overlay into the window's framebuffer
        of ``size`` (w, h) pixels over ``background`` (RGB); the caller swaps."""
        fbo = self.ctx.screen
        fbo.use()
        w, h = size
        self.ctx.viewport = (0, 0, w, h)
        fbo.clear(*background, 1.0)
        if self.last is not None:
            mode = Mode.PREMULTIPLIED if self.last.premultiplied else Mode.OPAQUE
            tex = self.last.texture if self.last.texture is not None else \
                self.presenter.upload("frame", self.last.image)
            self.presenter.draw(tex, mode, fit_viewport(tex.size, (w, h)), background)
        if self.overlay.visible and self.overlay.image is not None:
            img = self.overlay.image
            oh, ow = img.shape[:2]
            tex = self.presenter.upload("overlay", img)
            self.presenter.draw(tex, Mode.OVERLAY, (8, h - 8 - oh, ow, oh))

    def status(self, scene: Scene, settings: RenderSettings, kind: RendererKind, view: ViewMode,
               camera: Camera, fov_y: float, camera_text: str, message: str) -> Status:
        """The status panel's contents for ``camera`` (the size shown) and the last frame;
        ``camera_text`` names the training camera, ``message`` is the viewer's last word."""
        last = self.last
        mean = float(np.mean(self.frame_times)) if self.frame_times else 0.0
        s = settings
        sh = f"SH {min(s.sh_degree, scene.sh_degree) if s.sh_degree is not None else scene.sh_degree}" \
             f"/{scene.sh_degree}"
        bg = ",".join(f"{v:g}" for v in s.background)
        return Status(renderer=kind.value, fps=1.0 / mean if mean > 0 else 0.0, frame=mean,
                      sort=last.sort if last else 0.0, draw=last.draw if last else 0.0,
                      splats=last.splats if last else f"- / {scene.count:,}",
                      settings=f"{s.precision.value}  {sh}  {s.extent.value}  bg {bg}"
                               + ("  antialias" if s.antialias else ""),
                      size=(camera.width, camera.height), fov=fov_y,
                      view=view.value, camera=camera_text,
                      message="  ".join(m for m in (last.note if last else "", message) if m),
                      quality=last.quality if last else "")

    def release(self) -> None:
        """Release the renderer's and presenter's GPU objects (not the context)."""
        self.renderer.close()
        self.presenter.release()

