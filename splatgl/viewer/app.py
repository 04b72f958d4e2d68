"""The viewer's window loop: a glfw window, input handling, pacing; rendering is splatgl's.

:class:`Viewer` owns the window and its moderngl context and renders through the same
:class:`~splatgl.api.Renderer` (quad or tile path) as ``splatgl render``.  Its parts live
beside it: :mod:`.window` (opening the window, its callbacks), :mod:`.keys` (what each key
does), :mod:`.navigation` (the camera and the input in progress) and :mod:`.display` (the
frame, its presentation and the status panel).  It is drivable
from Python: the ``on_*`` methods are exactly what the glfw callbacks call, and :meth:`step`
runs one loop iteration (render if anything changed, present, swap), so tests inject input
and count frames without a person at the keyboard.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from pathlib import Path

import glfw

from ..cameras.camera import Camera
from ..cameras.registry import retarget
from ..scene.splats import Scene, SplatKind
from ..scene.settings import RendererKind, RenderSettings
from . import keys, pick
from .benchmark import orbit_benchmark
from .display import Display, lens_fov
from .modes import ViewMode
from .navigation import Navigation, orbit_distance
from .overlay import Status, key_help
from .pacing import Pacer, paced_frame
from .recorder import Recorder
from .screenshot import take_screenshot
from .window import close_window, connect, open_window, swap

#: Longest time step a held key acts over (a stalled frame must not fling the camera away).
_MAX_DT = 0.1


def _switch_renderer(v) -> None:
    """``v.switch_to``, set from another thread (``--renderer auto``: the CPU renderer's kernels
    compiled), becomes the renderer of the exact frame where the quad path's still is."""
    kind = v.__dict__.pop("switch_to", None)
    if kind is not None and v.kind is RendererKind.QUAD:
        v.kind = kind
        v.message = f"renderer auto -> {kind.value} (its kernels are compiled)"


@dataclass
class ViewerOptions:
    """How the viewer starts.

    Attributes:
        title: window title.
        visible: show the window (tests may hide it).
        screenshot_dir: where F12 writes ``splatgl-view-NNNN.png`` / ``.json``.
        render_args: ``splatgl render`` arguments that reproduce the scene and settings not held
            in :class:`RenderSettings` (scene path, ``--transform``, ``--drop-invalid``), for the
            command line printed with each screenshot.
        vsync: wait for the display's refresh on swap.
        up: (3,) world direction the orbit keeps up on screen (``--up``; default world -y).
        projection: show every view with this camera model instead (``--projection``; fisheye
            or equirectangular images are shown flat), ``fisheye_fov`` degrees for a fisheye.
        stereo: interpupillary distance (``--stereo``): the colour view shows both eyes side by
            side, each in half the window (depth and difference views stay one eye).
        target_fps: the frame-time budget while the camera moves (``--target-fps``; None: 10 on
            software GL, 60 on a GPU; 0: every frame exact), :mod:`.pacing`.
        scene_path: the scene's file, where the level-of-detail tree for budgets is cached.
        stream: a level of detail streamed from disk (``--memory``,
            :class:`splatgl.lod.stream_view.StreamedScene`): each frame draws what is resident
            (with a budget: the frame-time budget's level, :mod:`.pacing`) and draws again as
            chunks arrive, until exact at rest; screenshots wait for their chunks.
    """

    title: str = "splatgl view"
    visible: bool = True
    screenshot_dir: Path = Path(".")
    render_args: tuple[str, ...] = ()
    vsync: bool = True
    up: tuple[float, float, float] = (0.0, -1.0, 0.0)
    projection: str | None = None
    fisheye_fov: float | None = None
    stereo: float | None = None
    target_fps: float | None = None
    scene_path: Path | None = None
    stream: object | None = None


class Viewer:
    """A window showing ``scene`` from an interactive camera.

    ``camera`` gives the start view and the window size; ``cameras`` (e.g. a cameras.json)
    can be stepped through with N / Shift+N, starting at ``camera_index``.  The parts:
    :attr:`nav` (:class:`~.navigation.Navigation`, the camera and input in progress),
    :attr:`display` (:class:`~.display.Display`, the renderer, the frame and the status panel)
    and the window (:mod:`.window`); the viewer holds what is shown (scene, settings, renderer
    kind, view mode) and paces the loop.
    """

    def __init__(self, scene: Scene, settings: RenderSettings, camera: Camera,
                 cameras: list[Camera] | None = None, camera_index: int = 0,
                 kind: RendererKind = RendererKind.QUAD, options: ViewerOptions | None = None):
        self.scene, self.settings, self.kind = scene, settings, RendererKind(kind)
        self.options = options or ViewerOptions()
        self.nav = Navigation(camera, cameras, camera_index, self.options.up,
                              lambda cam: orbit_distance(self.scene, self.settings, cam))
        self.view = ViewMode.COLOR
        self.frames_rendered = self.presents = 0
        self.swap_idle = 0.0     # seconds the last swap waited without work (vsync), see present()
        self._rendered_key: tuple | None = None
        self.need_present = True
        self._clock = time.perf_counter()
        self._cursor = (0.0, 0.0)
        self.last_pixel = None   # the last Ctrl+click listing
        o = self.options
        self.pacer = Pacer(scene, o.target_fps, o.scene_path, o.stream)
        self.recorder = Recorder()                # K: the camera's flight as a path file
        self._queued: list | None = None   # input that acts after the draw in progress (callables)
        self._events = 0                                         # input events seen so far
        self.window, self.ctx, self.context_api = open_window(camera.width, camera.height, o.title,
                                                              o.visible, o.vsync)
        self.display = Display(self.ctx)
        connect(self.window, self)
        self.size = glfw.get_framebuffer_size(self.window)

    # ---------------------------------------------------------------------------- parts
    state = property(lambda self: self.nav.state, lambda self, value: setattr(self.nav, "state", value),
                     doc="The orbit camera (:class:`~.controls.ViewState`) now.")
    home = property(lambda self: self.nav.home, doc="The start view (R returns to it).")
    cameras = property(lambda self: self.nav.cameras, doc="The training cameras (N steps).")
    camera_index = property(lambda self: self.nav.index, doc="The training camera shown last.")
    renderer = property(lambda self: self.display.renderer, doc="The window context's Renderer.")
    overlay = property(lambda self: self.display.overlay, doc="The status panel.")
    last = property(lambda self: self.display.last, doc="The last FrameResult rendered (or None).")
    message = property(lambda self: self.display.message.current(),
                       lambda self, text: self.display.message.say(text),
                       doc="The status line's last word (it expires after a few seconds).")

    # ---------------------------------------------------------------------------- input
    def on_key(self, key: int, action: int, mods: int) -> None:
        """glfw key callback (what each key does: :func:`.keys.on_key`).  During a draw (a
        refinement step polls for input between its batches) keys are held back and act after
        it: a screenshot or a settings change never runs in the middle of a frame."""
        self._events += 1
        if self._queued is not None:
            self._queued.append(lambda: keys.on_key(self, key, action, mods))
            return
        keys.on_key(self, key, action, mods)

    def on_mouse_button(self, button: int, action: int, mods: int) -> None:
        """glfw mouse-button callback: left drag orbits, right or middle drag pans; a left
        click with Ctrl lists the pixel under the cursor (:meth:`list_pixel`; during a draw,
        after it)."""
        self._events += 1
        if button == glfw.MOUSE_BUTTON_LEFT and mods & glfw.MOD_CONTROL:
            if action == glfw.PRESS:
                cursor = self._cursor
                if self._queued is not None:
                    self._queued.append(lambda: self.list_pixel(*cursor))
                else:
                    self.list_pixel(*cursor)
            return
        self.nav.on_mouse_button(button, action)

    def on_cursor(self, x: float, y: float) -> None:
        """glfw cursor-position callback (window coordinates, y down)."""
        self._cursor = (x, y)
        self.nav.on_cursor(x, y, lambda: glfw.get_window_size(self.window)[1] or self.size[1])

    def list_pixel(self, x: float, y: float):
        """List the splats of the pixel under window point (``x``, ``y``) (window coordinates,
        y down): :func:`.pick.list_pixel`."""
        self.last_pixel = pick.list_pixel(self, x, y)
        return self.last_pixel

    def on_scroll(self, dx: float, dy: float) -> None:
        """glfw scroll callback: zoom towards the point under the cursor."""
        self._events += 1
        flat = self.options.projection is None     # a lens view zooms about its centre
        self.nav.on_scroll(dy, self._cursor if flat else None, glfw.get_window_size(self.window))

    def on_resize(self, width: int, height: int) -> None:
        """glfw framebuffer-size callback; 0 in either dimension (minimised) pauses rendering."""
        self._events += 1
        self.size = (int(width), int(height))
        self.need_present = True

    def on_focus(self, focused: bool) -> None:
        """glfw focus callback: keys released while unfocused never report, so drop them."""
        if not focused:
            self.nav.drop_input()

    def on_refresh(self) -> None:
        """glfw window-refresh callback: the window's contents were damaged."""
        self.need_present = True

    # ---------------------------------------------------------------------------- actions
    def step_camera(self, delta: int) -> None:
        """Jump to the next (``delta`` 1) or previous training camera."""
        self.message = self.nav.step_camera(delta)

    def set_settings(self, **changes) -> None:
        """Replace render settings; the GPU state of the old ones is released (one scene copy)."""
        new = replace(self.settings, **changes)
        if new != self.settings:
            self.pacer.release_session()
            self.display.new_renderer()
            self.settings = new

    def camera(self) -> Camera:
        """The current camera at the window's framebuffer size (world frame)."""
        cam = self.nav.camera(max(self.size[0], 1), max(self.size[1], 1))
        if self.options.projection is not None:   # fisheye or equirect, shown flat
            cam = retarget(cam, self.options.projection, self.options.fisheye_fov)
        return cam

    def screenshot(self) -> tuple[Path, Path]:
        """F12: :func:`.screenshot.take_screenshot` (the exact render, never the draft)."""
        return take_screenshot(self)

    # ---------------------------------------------------------------------------- loop
    @property
    def animating(self) -> bool:
        """Whether input is in progress (held keys or a drag): poll instead of waiting."""
        return self.nav.animating

    def step(self, dt: float | None = None) -> bool:
        """One loop iteration: held keys, render when anything changed, present.

        ``dt`` overrides the seconds held keys act over (default: since the last step).
        Returns whether a new frame was rendered.
        """
        now = time.perf_counter()
        dt = min(now - self._clock if dt is None else dt, _MAX_DT)
        self._clock = now
        _switch_renderer(self)
        self.nav.apply_held(dt)
        if self.recorder.recording:
            self.recorder.add(self.nav.camera(max(self.size[0], 1), max(self.size[1], 1)))
        if self.size[0] <= 0 or self.size[1] <= 0:
            return False  # minimised: nothing to draw into
        glfw.make_context_current(self.window)
        camera = self.camera()
        key = (self.state, self.size, self.settings, self.kind, self.view, _generation(self))
        t0 = time.perf_counter()
        if self.paced:
            rendered = paced_frame(self, camera, key)
        elif key != self._rendered_key:
            try:
                self.display.render(self.scene_now(camera), camera, self.settings, self.kind,
                                    self.view, self.options.stereo)
            except NotImplementedError as exc:  # e.g. the quad path and 2DGS surfels
                self.message = str(exc)
                self.kind = RendererKind.TILE
                return False
            rendered = True
        else:
            rendered = False
        if rendered:
            self._rendered_key = key
            self.frames_rendered += 1
            self.need_present = True
            self._frame_start = t0
        if self.display.panel(self._status(camera), self.size, now, not rendered and self.need_present):
            self.need_present = True
        if self.need_present:
            self.present()
            if rendered:
                seconds = time.perf_counter() - self._frame_start
                paced = self.paced
                self.display.record_frame_time(seconds, paced and self.pacer.moved,
                                               not paced or self.pacer.exact)
                if paced:     # the window's share of a moving frame comes off the draw's
                    self.pacer.note_frame(seconds - self.swap_idle, self.last.sort + self.last.draw)
        return rendered

    @property
    def paced(self) -> bool:
        """Whether this frame goes through the frame-time budget (:mod:`.pacing`): the colour
        view of the quad path or the CPU renderer (quad drafts, its exact frame at rest), one
        eye, with a budget set (streamed, ``--memory``: the quad path's)."""
        return (self.view is ViewMode.COLOR and self.kind in (RendererKind.QUAD, RendererKind.CPU)
                and self.options.stereo is None and self.scene.kind is SplatKind.GAUSSIAN_3D
                and (self.options.stream is None or self.kind is RendererKind.QUAD)
                and self.pacer.enabled(self.renderer))

    def present(self) -> None:
        """Draw the last frame (and the overlay) into the window and swap."""
        self.display.draw(self.size, self.settings.background, (self.state, self.size))
        self.swap_idle = swap(self.window, self.options.vsync)   # vsync's wait: not a cost
        self.presents += 1
        self.need_present = False

    def scene_now(self, camera: Camera, exact: bool = False) -> Scene:
        """The scene to draw for ``camera`` (a streamed one's: :func:`_streamed`)."""
        return _streamed(self, camera, exact)

    def _status(self, camera: Camera) -> Status:
        cam = f"camera {self.camera_index + 1}/{len(self.cameras)}" if self.cameras else ""
        return _stream_status(self.display.status(
            self.scene, self.settings, self.kind, self.view, camera,
            lens_fov(camera, self.state.fov_y), cam, self.paced), self.options.stream)

    def should_close(self) -> bool:
        return bool(glfw.window_should_close(self.window))

    def run(self) -> None:
        """Loop until closed: poll while input is in progress, else sleep until an event."""
        print("keys:\n" + key_help(), flush=True)
        while not self.should_close():
            if self.animating or (self.paced and self.pacer.refining and not self.pacer.awaiting):
                glfw.poll_events()
            else:
                glfw.wait_events_timeout(1.0 / 4.0)
            if not self.should_close():    # Esc: quit now, not after one more (exact) frame
                self.step()

    def benchmark(self, frames: int) -> dict[str, float]:
        """``--benchmark``: :func:`.benchmark.orbit_benchmark` (a method, so harnesses such as
        the peer race can wrap it)."""
        return orbit_benchmark(self, frames)

    # ---------------------------------------------------------------------------- teardown
    def close(self) -> None:
        """Release GPU objects, close the window and shut glfw down."""
        if getattr(self, "window", None):
            glfw.make_context_current(self.window)
            self.pacer.release()
            self.display.release()
            self.ctx.release()
        close_window(getattr(self, "window", None))
        self.window = None

    def __enter__(self) -> "Viewer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _generation(viewer: Viewer) -> int | None:
    """Chunks a streamed level of detail has received (a new one draws the frame again)."""
    stream = viewer.options.stream
    return None if stream is None else stream.generation


def _streamed(viewer: Viewer, camera: Camera, exact: bool) -> Scene:
    """The scene shown, or a streamed level of detail's resident cut for ``camera``
    (``exact``: waiting for every chunk it needs)."""
    stream = viewer.options.stream
    if stream is None:
        return viewer.scene
    return (stream.exact_scene if exact else stream.scene_for)(camera, viewer.settings)


def _stream_status(status: Status, stream) -> Status:
    """The status panel with a streamed level of detail's resident memory and chunks."""
    if stream is None:
        return status
    return replace(status, message="  ".join(m for m in (status.message, stream.summary()) if m))
