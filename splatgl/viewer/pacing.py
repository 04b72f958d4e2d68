"""The viewer's frame-time budget: colour frames of the quad path through an interactive session
(with ``--renderer cpu``: the quad path's drafts while moving, the CPU renderer's exact frame
at rest).

While the camera moves, each frame is drawn at the level the budget picks (render scale, splat
budget, SH degree; :mod:`splatgl.interactive.budget`); when it rests, the session refines to the
exact frame, one interruptible step per loop iteration (:mod:`splatgl.interactive.session`).
Other views (depth, difference, the tile renderer, stereo) are drawn exactly, as before.

The budget defaults to 10 frames a second where the GL renderer is a software rasteriser
(llvmpipe) and 60 elsewhere (:func:`splatgl.interactive.session.default_fps`); ``--target-fps
0`` turns it off.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import glfw

from ..api import Renderer
from ..cameras.camera import Camera
from ..interactive.budget import check_fps
from ..interactive.lod_cache import LodProvider
from ..interactive.session import Session, default_fps
from ..interactive.stream_levels import streamed_session
from ..scene.splats import Scene
from ..scene.settings import RendererKind, RenderSettings
from ..renderers.registry import DEFAULT_RENDERER
from .modes import FrameResult, splats_phrase

class Pacer:
    """The budgeted colour frames of one viewer (see the module doc).

    ``fps``: frames a second to aim at while moving (None: :func:`default_fps`; 0: no budget,
    every frame exact); ``scene_path``: the scene's file, for the level-of-detail cache;
    ``stream``: a level of detail streamed from disk (``--memory``,
    :class:`splatgl.lod.stream_view.StreamedScene`; ``scene`` is then its framing proxy), drawn
    through :func:`~splatgl.interactive.stream_levels.streamed_session`.
    """

    def __init__(self, scene: Scene, fps: float | None, scene_path: Path | None = None,
                 stream=None):
        self.scene, self.fps_asked, self.scene_path = scene, check_fps(fps), scene_path
        self.stream = stream
        self.lod: LodProvider | None = None
        self.session: Session | None = None
        self._owner: tuple | None = None
        self.shown: FrameResult | None = None   # the last frame handed to the window

    def fps(self, renderer: Renderer) -> float:
        return default_fps(renderer) if self.fps_asked is None else self.fps_asked

    def enabled(self, renderer: Renderer) -> bool:
        return self.fps(renderer) > 0.0

    def _session(self, renderer: Renderer, settings: RenderSettings,
                 kind: RendererKind = DEFAULT_RENDERER) -> Session:
        owner = (id(renderer), settings, kind)
        if self.session is None or self._owner != owner:
            self.release_session()
            if self.stream is not None:
                self.session = streamed_session(renderer, self.stream, settings,
                                                1.0 / self.fps(renderer))
                self._owner = owner
                return self.session
            if self.lod is None:
                self.lod = LodProvider(self.scene, self.scene_path)
            self.session = Session(renderer, self.scene, settings, 1.0 / self.fps(renderer), self.lod,
                                   exact_kind=kind)
            self._owner = owner
        return self.session

    def frame(self, renderer: Renderer, camera: Camera, settings: RenderSettings,
              input_pending: Callable[[], bool] | None = None,
              kind: RendererKind = DEFAULT_RENDERER) -> FrameResult | None:
        """The next frame for ``camera``: a moving frame, or the next refinement step at rest
        (None: nothing new, or a refinement step interrupted by input).  ``kind``: the
        renderer of the exact frame (the quad path, or the CPU renderer after quad drafts)."""
        session = self._session(renderer, settings, kind)
        drawn = session.frame(camera, input_pending)
        if drawn is None:
            return None
        self.shown = FrameResult(drawn.texture, None, True, drawn.sort,
                                 max(drawn.seconds - drawn.sort, 0.0),
                                 splats_phrase(drawn, self.scene.count),
                                 quality=self.describe())
        return self.shown

    def redraw(self) -> None:
        """The window showed another frame since (another view or renderer): the next
        :meth:`frame` draws anew, even for the same camera."""
        if self.session is not None:
            self.session.redraw()

    def note_frame(self, seconds: float, drawn: float) -> None:
        """The window's whole last frame took ``seconds``, its draw ``drawn`` of them: where it
        was a moving frame, the rest (present, swap, the loop) comes off the draw's budget
        (:meth:`~splatgl.interactive.session.Session.note_overhead`)."""
        if self.session is not None and self.session.moved:
            self.session.note_overhead(seconds - drawn)

    @property
    def refining(self) -> bool:
        """Whether refinement steps are left (the loop should poll, not wait for events)."""
        return self.session is not None and self.session.shown is not None and (
            not self.session.exact or self.session.pending)

    @property
    def awaiting(self) -> bool:
        """Whether the frame at rest waits for streamed chunks only (the loop may sleep: each
        arrival wakes it)."""
        return self.session is not None and self.session.awaiting

    @property
    def exact(self) -> bool:
        return self.session is not None and self.session.exact

    @property
    def moved(self) -> bool:
        """Whether the last frame drawn was a moving frame (not a refinement step)."""
        return self.session is not None and self.session.moved

    def describe(self) -> str:
        """The status line: whether the frame shown is moving, refining or exact, and its level."""
        s = self.session
        if s is None or s.shown is None:
            return ""
        if s.exact:
            return "exact (as splatgl render)"
        state = "refining" if s.status != "moving" else "moving"
        return f"{state}: {s.shown.level.describe()}"

    def release_session(self) -> None:
        if self.session is not None:
            self.session.release()
            self.session = None
            self._owner = None

    def release(self) -> None:
        self.release_session()


def paced_frame(viewer, camera: Camera, key: tuple) -> bool:
    """In ``viewer`` (:class:`~.app.Viewer`), draw the budgeted frame (the view ``key`` changed)
    or the next refinement step (at rest); returns whether a new frame was drawn.

    A refinement step polls glfw between its batches: any input (a key, a button, the wheel, a
    resize, a drag that moved the camera, a held key) abandons it.  Keys that arrive during the
    draw are held back and act after it, so a screenshot or a settings change never runs in the
    middle of a frame.
    """
    v = viewer
    if key == v._rendered_key and not v.pacer.refining:
        return False
    if v.last is None or v.last is not v.pacer.shown:   # what is shown changed (view, renderer)
        v.pacer.redraw()
    start_events, start_state = v._events, (v.state, v.size)

    def input_pending() -> bool:
        glfw.poll_events()
        return (v._events != start_events or (v.state, v.size) != start_state or v.nav.animating
                or v.should_close())

    v._queued = []
    try:
        frame = v.pacer.frame(v.renderer, camera, v.settings, input_pending, v.kind)
    finally:
        queued, v._queued = v._queued, None
        for act in queued:
            act()
    if frame is None:
        return False
    v.display.show(frame)
    return True
