"""The viewer's window loop: a glfw window, input handling, pacing; rendering is splatgl's.

:class:`Viewer` owns the window and its moderngl context and renders through the same
:class:`~splatgl.api.Renderer` (quad or tile path) as ``splatgl render``.  It is drivable
from Python: the ``on_*`` methods are exactly what the glfw callbacks call, and :meth:`step`
runs one loop iteration (render if anything changed, present, swap), so tests inject input
and count frames without a person at the keyboard.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from pathlib import Path

import glfw
import numpy as np

from ..cameras.camera import Camera
from ..errors import SplatglError
from ..cameras.registry import retarget
from ..renderers.stereo import StereoLayout, StereoRenderer
from ..gl.context import REQUIRED_VERSION, create_glfw_context, create_glfw_window
from ..api import Renderer
from ..model.scene import Scene
from ..model.settings import Precision, RendererKind, RenderSettings
from . import controls
from .frames import FrameResult, ViewMode, render_frame
from .overlay import Overlay, Status, key_help, status_lines
from .present import Mode, Presenter, fit_viewport
from .screenshot import save_screenshot

#: Held keys that fly, as (forward, right, up) directions.
_FLY_KEYS = {
    glfw.KEY_W: (1, 0, 0), glfw.KEY_UP: (1, 0, 0), glfw.KEY_S: (-1, 0, 0), glfw.KEY_DOWN: (-1, 0, 0),
    glfw.KEY_D: (0, 1, 0), glfw.KEY_RIGHT: (0, 1, 0), glfw.KEY_A: (0, -1, 0), glfw.KEY_LEFT: (0, -1, 0),
    glfw.KEY_E: (0, 0, 1), glfw.KEY_Q: (0, 0, -1),
}
#: Held keys that roll, degrees per second.
_ROLL_KEYS = {glfw.KEY_Z: -60.0, glfw.KEY_X: 60.0}
_PRECISIONS = (Precision.RGBA32F, Precision.RGBA16F, Precision.RGBA8)
#: Longest time step a held key acts over (a stalled frame must not fling the camera away).
_MAX_DT = 0.1


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


class Viewer:
    """A window showing ``scene`` from an interactive camera.

    ``camera`` gives the start view and the window size; ``cameras`` (e.g. a cameras.json)
    can be stepped through with N / Shift+N, starting at ``camera_index``.
    """

    def __init__(self, scene: Scene, settings: RenderSettings, camera: Camera,
                 cameras: list[Camera] | None = None, camera_index: int = 0,
                 kind: RendererKind = RendererKind.QUAD, options: ViewerOptions | None = None):
        self.scene, self.settings, self.kind = scene, settings, RendererKind(kind)
        self.options = options or ViewerOptions()
        self.cameras = list(cameras or [])
        self.camera_index = camera_index
        self.home = controls.from_camera(camera, self._orbit_distance(camera), self.options.up)
        self.state = self.home
        # A camera from a file (the start camera, a training camera) is shown exactly, with its
        # own intrinsics, until the user moves: the orbit state carries only pose and fov.
        self._exact: tuple[controls.ViewState, Camera] | None = (self.home, camera)
        self.view = ViewMode.COLOR
        self.message = ""
        self.frames_rendered = 0
        self.presents = 0
        self.last: FrameResult | None = None
        self._frame_times: list[float] = []
        self._held: set[int] = set()
        self._shift = False
        self._drag: int | None = None
        self._cursor: tuple[float, float] | None = None
        self._rendered_key: tuple | None = None
        self._need_present = True
        self._clock = time.perf_counter()
        self._open_window(camera.width, camera.height)

    # ---------------------------------------------------------------------------- set-up
    def _orbit_distance(self, camera: Camera) -> float:
        """Orbit about the scene centre's depth along the view axis (at least 10% of its size)."""
        lo, hi = self.scene.robust_bounds
        centre = 0.5 * (lo + hi)
        radius = max(self.scene.robust_radius, 1e-6)
        if self.settings.model is not None:
            centre = self.settings.model.apply_points(centre[None])[0]
            radius *= self.settings.model.scale
        depth = float((centre - camera.center) @ (camera.rotation[2] / camera.scale))
        return max(depth, 0.1 * radius)

    def _open_window(self, width: int, height: int) -> None:
        if not glfw.init():
            raise SplatglError("cannot open a window: glfw failed to initialise "
                               "(no display? set DISPLAY, e.g. run under Xvfb)")
        try:
            self.window, version, self.context_api = create_glfw_window(width, height, self.options.title,
                                                      self.options.visible)
            if version[0] * 100 + version[1] * 10 < REQUIRED_VERSION:
                raise SplatglError(
                    f"only an OpenGL {version[0]}.{version[1]} window context is available; the "
                    "viewer needs 4.3 (storage buffers for the quad path, compute shaders for "
                    "the tile path). Use `splatgl render` (headless EGL) instead")
            self.ctx = create_glfw_context()
        except Exception:
            self._terminate()
            raise
        glfw.swap_interval(1 if self.options.vsync else 0)
        self.renderer = Renderer(self.ctx)
        self.presenter = Presenter(self.ctx)
        self.overlay = Overlay()
        w = self.window
        glfw.set_key_callback(w, lambda _w, key, sc, action, mods: self.on_key(key, action, mods))
        glfw.set_mouse_button_callback(w, lambda _w, b, action, mods: self.on_mouse_button(b, action, mods))
        glfw.set_cursor_pos_callback(w, lambda _w, x, y: self.on_cursor(x, y))
        glfw.set_scroll_callback(w, lambda _w, dx, dy: self.on_scroll(dx, dy))
        glfw.set_framebuffer_size_callback(w, lambda _w, fw, fh: self.on_resize(fw, fh))
        glfw.set_window_refresh_callback(w, lambda _w: self.on_refresh())
        glfw.set_window_focus_callback(w, lambda _w, focused: self.on_focus(bool(focused)))
        self.size = glfw.get_framebuffer_size(w)

    # ---------------------------------------------------------------------------- input
    def on_key(self, key: int, action: int, mods: int) -> None:
        """glfw key callback."""
        self._shift = bool(mods & glfw.MOD_SHIFT)
        ctrl = bool(mods & glfw.MOD_CONTROL)
        if action == glfw.RELEASE:
            self._held.discard(key)
            return
        if (key in _FLY_KEYS or key in _ROLL_KEYS) and not ctrl:
            self._held.add(key)  # acts in step() for as long as it is held
            return
        if action != glfw.PRESS and key not in (glfw.KEY_LEFT_BRACKET, glfw.KEY_RIGHT_BRACKET,
                                                glfw.KEY_MINUS, glfw.KEY_EQUAL, glfw.KEY_KP_ADD,
                                                glfw.KEY_KP_SUBTRACT):
            return  # the rest act once per press, not on auto-repeat
        if key == glfw.KEY_ESCAPE:
            glfw.set_window_should_close(self.window, True)
        elif key == glfw.KEY_R:
            self.state = controls.reset(self.state, self.home)
        elif key in (glfw.KEY_LEFT_BRACKET, glfw.KEY_MINUS, glfw.KEY_KP_SUBTRACT):
            self.state = controls.change_fov(self.state, -2.0)
        elif key in (glfw.KEY_RIGHT_BRACKET, glfw.KEY_EQUAL, glfw.KEY_KP_ADD):
            self.state = controls.change_fov(self.state, 2.0)
        elif key in (glfw.KEY_N, glfw.KEY_PAGE_DOWN, glfw.KEY_PAGE_UP):
            back = key == glfw.KEY_PAGE_UP or (key == glfw.KEY_N and self._shift)
            self.step_camera(-1 if back else 1)
        elif key == glfw.KEY_T:
            if self.kind is RendererKind.TILE or self._tile_allowed("T"):
                self.toggle_renderer()
        elif glfw.KEY_0 <= key <= glfw.KEY_3:
            self.set_settings(sh_degree=key - glfw.KEY_0)
        elif key == glfw.KEY_P:
            i = _PRECISIONS.index(self.settings.precision)
            self.set_settings(precision=_PRECISIONS[(i + 1) % len(_PRECISIONS)])
        elif key == glfw.KEY_D and ctrl:
            self.view = ViewMode.COLOR if self.view is ViewMode.DEPTH else ViewMode.DEPTH
        elif key == glfw.KEY_TAB:
            modes = list(ViewMode)
            view = modes[(modes.index(self.view) + 1) % len(modes)]
            if view is ViewMode.DIFFERENCE and not self._tile_allowed("Tab"):
                view = modes[(modes.index(view) + 1) % len(modes)]   # skip it
            self.view = view
        elif key == glfw.KEY_C:
            if self.view is ViewMode.DIFFERENCE:
                self.view = ViewMode.COLOR
            elif self._tile_allowed("C"):
                self.view = ViewMode.DIFFERENCE
        elif key == glfw.KEY_F12 or (key == glfw.KEY_S and ctrl):
            self.screenshot()
        elif key == glfw.KEY_I:
            self.overlay.visible = not self.overlay.visible
        elif key == glfw.KEY_H:
            self.overlay.show_keys = not self.overlay.show_keys
            if self.overlay.show_keys:
                print("keys:\n" + key_help(), flush=True)
        self._need_present = True

    def on_mouse_button(self, button: int, action: int, mods: int) -> None:
        """glfw mouse-button callback: left drag orbits, right or middle drag pans."""
        if action == glfw.PRESS and self._drag is None:
            self._drag = button
            self._cursor = None
        elif action == glfw.RELEASE and button == self._drag:
            self._drag = None

    def on_cursor(self, x: float, y: float) -> None:
        """glfw cursor-position callback (window coordinates, y down)."""
        if self._drag is not None and self._cursor is not None:
            dx, dy = x - self._cursor[0], y - self._cursor[1]
            if self._drag == glfw.MOUSE_BUTTON_LEFT:
                self.state = controls.orbit_drag(self.state, dx, dy)
            else:
                wh = glfw.get_window_size(self.window)[1] or self.size[1]
                self.state = controls.pan(self.state, dx, dy, max(wh, 1))
        self._cursor = (x, y)

    def on_scroll(self, dx: float, dy: float) -> None:
        """glfw scroll callback: zoom."""
        self.state = controls.zoom(self.state, dy)

    def on_resize(self, width: int, height: int) -> None:
        """glfw framebuffer-size callback; 0 in either dimension (minimised) pauses rendering."""
        self.size = (int(width), int(height))
        self._need_present = True

    def on_focus(self, focused: bool) -> None:
        """glfw focus callback: keys released while unfocused never report, so drop them."""
        if not focused:
            self._held.clear()
            self._drag = None

    def on_refresh(self) -> None:
        """glfw window-refresh callback: the window's contents were damaged."""
        self._need_present = True

    # ---------------------------------------------------------------------------- actions
    def step_camera(self, delta: int) -> None:
        """Jump to the next (``delta`` 1) or previous training camera."""
        if not self.cameras:
            self.message = "no camera list (start with --camera cameras.json)"
            return
        self.camera_index = controls.step_index(self.camera_index, len(self.cameras), delta)
        cam = self.cameras[self.camera_index]
        self.state = controls.from_camera(cam, self._orbit_distance(cam), self.state.up)
        self._exact = (self.state, cam)
        self.message = f"training camera {self.camera_index + 1}/{len(self.cameras)}"

    def _tile_allowed(self, key: str) -> bool:
        """Whether the tile renderer can draw the current view (T, and the difference view's
        other side); if not, the status line says why and the key changes nothing."""
        try:
            self.camera().model.check_support(False, RendererKind.TILE.value)
        except SplatglError as exc:
            self.message = f"{key} refused: {str(exc).split(';')[0]}"
            return False
        return True

    def toggle_renderer(self) -> None:
        self.kind = RendererKind.TILE if self.kind is RendererKind.QUAD else RendererKind.QUAD

    def set_settings(self, **changes) -> None:
        """Replace render settings; the GPU state of the old ones is released (one scene copy)."""
        new = replace(self.settings, **changes)
        if new != self.settings:
            self.renderer.close()  # the context is the window's: only paths and programs go
            self.renderer = Renderer(self.ctx)
            self.settings = new

    def camera(self) -> Camera:
        """The current camera at the window's framebuffer size (world frame)."""
        width, height = max(self.size[0], 1), max(self.size[1], 1)
        if self._exact is not None and self._exact[0] == self.state:
            cam = controls.fit_camera(self._exact[1], width, height)
        else:
            cam = controls.to_camera(self.state, width, height)
        if self.options.projection is not None:   # fisheye or equirect, shown flat
            cam = retarget(cam, self.options.projection, self.options.fisheye_fov)
        return cam

    def _render(self, camera: Camera) -> FrameResult:
        """One frame of ``camera``: :func:`render_frame`, or with ``options.stereo`` (colour
        view) both eyes side by side, each eye the view fitted to half the window."""
        if self.options.stereo is None or self.view is not ViewMode.COLOR:
            return render_frame(self.renderer, self.scene, camera, self.settings, self.kind, self.view)
        half = controls.fit_camera(camera, max(camera.width // 2, 1), camera.height)
        stereo = StereoRenderer(self.renderer, self.options.stereo, StereoLayout.SIDE_BY_SIDE)
        t0 = time.perf_counter()
        image = stereo.render(self.scene, half, self.settings, self.kind)
        if image.shape[1] < camera.width:   # an odd width: one column of background
            pad = np.zeros((image.shape[0], camera.width - image.shape[1], 4), np.float32)
            pad[..., :3] = self.settings.background
            image = np.concatenate([image, pad], axis=1)
        return FrameResult(None, image, False, 0.0, time.perf_counter() - t0,
                           f"stereo, IPD {self.options.stereo:g}")

    def screenshot(self) -> tuple[Path, Path]:
        """Write what ``splatgl render`` writes from the current camera, and that camera; in
        stereo, both eyes side by side (``--stereo``) from the camera of one eye's half."""
        glfw.make_context_current(self.window)
        camera = self.camera()
        if self.options.stereo is not None:
            camera = controls.fit_camera(camera, max(camera.width // 2, 1), camera.height)
        png, js, command = save_screenshot(self.renderer, self.scene, camera, self.settings,
                                           self.kind, self.options.screenshot_dir,
                                           self.options.render_args, self.options.stereo)
        self.message = f"saved {png.name} + {js.name}"
        print(f"wrote {png} and {js}; reproduce with:\n  {command}", flush=True)
        self._need_present = True
        return png, js

    # ---------------------------------------------------------------------------- loop
    def _apply_held_keys(self, dt: float) -> None:
        if not self._held:
            return
        speed = controls.fly_speed(self.home) * (4.0 if self._shift else 1.0) * dt
        f = r = u = 0.0
        for key in self._held:
            if key in _FLY_KEYS:
                df, dr, du = _FLY_KEYS[key]
                f, r, u = f + df, r + dr, u + du
            elif key in _ROLL_KEYS:
                self.state = controls.roll_by(self.state, _ROLL_KEYS[key] * dt)
        if f or r or u:
            self.state = controls.fly(self.state, f * speed, r * speed, u * speed)

    @property
    def animating(self) -> bool:
        """Whether input is in progress (held keys or a drag): poll instead of waiting."""
        return bool(self._held) or self._drag is not None

    def step(self, dt: float | None = None) -> bool:
        """One loop iteration: held keys, render when anything changed, present.

        ``dt`` overrides the seconds held keys act over (default: since the last step).
        Returns whether a new frame was rendered.
        """
        now = time.perf_counter()
        dt = min(now - self._clock if dt is None else dt, _MAX_DT)
        self._clock = now
        self._apply_held_keys(dt)
        if self.size[0] <= 0 or self.size[1] <= 0:
            return False  # minimised: nothing to draw into
        glfw.make_context_current(self.window)
        camera = self.camera()
        key = (self.state, self.size, self.settings, self.kind, self.view)
        rendered = False
        if key != self._rendered_key:
            t0 = time.perf_counter()
            try:
                self.last = self._render(camera)
            except NotImplementedError as exc:  # e.g. the quad path and 2DGS surfels
                self.message = str(exc)
                self.kind = RendererKind.TILE
                return False
            self._rendered_key = key
            self.frames_rendered += 1
            rendered = True
            self._need_present = True
            self._frame_start = t0
        lines = status_lines(self._status(camera))
        if self.overlay.visible and self.overlay.update(lines, now, force=not rendered and self._need_present):
            self._need_present = True
        if self._need_present:
            self.present()
            if rendered:
                self._frame_times = (self._frame_times + [time.perf_counter() - self._frame_start])[-20:]
        return rendered

    def present(self) -> None:
        """Draw the last frame (and the overlay) into the window and swap."""
        fbo = self.ctx.screen
        fbo.use()
        w, h = self.size
        self.ctx.viewport = (0, 0, w, h)
        fbo.clear(*self.settings.background, 1.0)
        if self.last is not None:
            mode = Mode.PREMULTIPLIED if self.last.premultiplied else Mode.OPAQUE
            tex = self.last.texture if self.last.texture is not None else \
                self.presenter.upload("frame", self.last.image)
            self.presenter.draw(tex, mode, fit_viewport(tex.size, (w, h)), self.settings.background)
        if self.overlay.visible and self.overlay.image is not None:
            img = self.overlay.image
            oh, ow = img.shape[:2]
            tex = self.presenter.upload("overlay", img)
            self.presenter.draw(tex, Mode.OVERLAY, (8, h - 8 - oh, ow, oh))
        glfw.swap_buffers(self.window)
        self.presents += 1
        self._need_present = False

    def _status(self, camera: Camera) -> Status:
        last = self.last
        mean = float(np.mean(self._frame_times)) if self._frame_times else 0.0
        s = self.settings
        sh = f"SH {min(s.sh_degree, self.scene.sh_degree) if s.sh_degree is not None else self.scene.sh_degree}" \
             f"/{self.scene.sh_degree}"
        bg = ",".join(f"{v:g}" for v in s.background)
        cam = (f"camera {self.camera_index + 1}/{len(self.cameras)}" if self.cameras else "")
        return Status(renderer=self.kind.value, fps=1.0 / mean if mean > 0 else 0.0, frame=mean,
                      sort=last.sort if last else 0.0, draw=last.draw if last else 0.0,
                      splats=last.splats if last else f"- / {self.scene.count:,}",
                      settings=f"{s.precision.value}  {sh}  {s.extent.value}  bg {bg}"
                               + ("  antialias" if s.antialias else ""),
                      size=(camera.width, camera.height), fov=self.state.fov_y,
                      view=self.view.value, camera=cam,
                      message="  ".join(m for m in (last.note if last else "", self.message) if m))

    def should_close(self) -> bool:
        return bool(glfw.window_should_close(self.window))

    def run(self) -> None:
        """Loop until closed: poll while input is in progress, else sleep until an event."""
        print("keys:\n" + key_help(), flush=True)
        while not self.should_close():
            if self.animating:
                glfw.poll_events()
            else:
                glfw.wait_events_timeout(1.0 / 4.0)
            self.step()

    def benchmark(self, frames: int) -> dict[str, float]:
        """Render ``frames`` frames of a scripted orbit (yaw steps of 360 / (frames + 1) degrees,
        so every frame is a new view), each presented and swapped; returns mean seconds per
        frame and per stage, and fps."""
        totals = {"frame": 0.0, "sort": 0.0, "draw": 0.0}
        start = self.state
        for i in range(1, frames + 1):
            glfw.poll_events()
            self.state = replace(start, yaw=start.yaw + 360.0 * i / (frames + 1))
            t0 = time.perf_counter()
            if not self.step(dt=0.0):
                raise SplatglError("benchmark: the window cannot be drawn into (minimised?)")
            self.ctx.finish()
            totals["frame"] += time.perf_counter() - t0
            totals["sort"] += self.last.sort
            totals["draw"] += self.last.draw
        out = {k: v / frames for k, v in totals.items()}
        out["fps"] = 1.0 / out["frame"]
        self.state = start
        return out

    # ---------------------------------------------------------------------------- teardown
    def _terminate(self) -> None:
        if getattr(self, "window", None):
            glfw.destroy_window(self.window)
            self.window = None
        glfw.terminate()

    def close(self) -> None:
        """Release GPU objects, close the window and shut glfw down."""
        if getattr(self, "window", None):
            glfw.make_context_current(self.window)
            self.renderer.close()
            self.presenter.release()
            self.ctx.release()
        self._terminate()

    def __enter__(self) -> "Viewer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

