"""The camera under the user's hands: orbit state, held keys, mouse drags, training cameras.

:class:`Navigation` keeps what the viewer's camera input changes and turns it into a
:class:`~splatgl.cameras.camera.Camera` for the window's size.  It opens no window and draws
nothing: the viewer forwards glfw input here (key and button codes are glfw's), and the state
changes themselves are the pure functions of :mod:`.controls`.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Callable

import glfw
import numpy as np

from ..cameras.camera import Camera
from ..cameras.up import UP_AXES
from ..scene.splats import Scene
from ..scene.settings import RenderSettings
from . import controls

#: Held keys that fly, as (forward, right, up) directions.
FLY_KEYS = {
    glfw.KEY_W: (1, 0, 0), glfw.KEY_UP: (1, 0, 0), glfw.KEY_S: (-1, 0, 0), glfw.KEY_DOWN: (-1, 0, 0),
    glfw.KEY_D: (0, 1, 0), glfw.KEY_RIGHT: (0, 1, 0), glfw.KEY_A: (0, -1, 0), glfw.KEY_LEFT: (0, -1, 0),
    glfw.KEY_E: (0, 0, 1), glfw.KEY_Q: (0, 0, -1),
}
#: Held keys that roll, degrees per second.
ROLL_KEYS = {glfw.KEY_Z: -60.0, glfw.KEY_X: 60.0}


def orbit_distance(scene: Scene, settings: RenderSettings, camera: Camera) -> float:
    """Orbit about the scene centre's depth along the view axis (at least 10% of its size);
    world units, the scene placed by ``settings.transform``."""
    lo, hi = scene.robust_bounds
    centre = 0.5 * (lo + hi)
    radius = max(scene.robust_radius, 1e-6)
    if settings.transform is not None:
        centre = settings.transform.apply_points(centre[None])[0]
        radius *= settings.transform.scale
    depth = float((centre - camera.center) @ (camera.rotation[2] / camera.scale))
    return max(depth, 0.1 * radius)


class Navigation:
    """The orbit camera and the input in progress.

    ``camera`` is the start view (its pose and field of view become :attr:`home`); ``cameras``
    (e.g. a cameras.json) can be stepped through from ``index``; ``distance(camera)`` gives the
    orbit distance of a camera jumped to (see :func:`orbit_distance`); ``up`` (3,) is the world
    direction kept up on screen.
    """

    def __init__(self, camera: Camera, cameras: list[Camera] | None, index: int,
                 up: tuple[float, float, float], distance: Callable[[Camera], float]):
        self.distance = distance
        self.cameras = list(cameras or [])
        self.index = index
        self.home = controls.from_camera(camera, distance(camera), up)
        self.state = self.home
        # A camera from a file (the start camera, a training camera) is shown exactly, with its
        # own intrinsics, until the user moves: the orbit state carries only pose and fov.
        self.exact: tuple[controls.ViewState, Camera] | None = (self.home, camera)
        self.held: set[int] = set()
        self.shift = False
        self.drag: int | None = None
        self.cursor: tuple[float, float] | None = None

    @property
    def animating(self) -> bool:
        """Whether input is in progress (held keys or a drag)."""
        return bool(self.held) or self.drag is not None

    # ---------------------------------------------------------------------------- keys
    def hold(self, key: int) -> bool:
        """Start holding ``key`` if it flies or rolls (it acts in :meth:`apply_held` until
        released); returns whether it does."""
        if key in FLY_KEYS or key in ROLL_KEYS:
            self.held.add(key)
            return True
        return False

    def release(self, key: int) -> None:
        self.held.discard(key)

    def apply_held(self, dt: float) -> None:
        """Move by the held keys over ``dt`` seconds (Shift: 4x faster)."""
        if not self.held:
            return
        speed = controls.fly_speed(self.home) * (4.0 if self.shift else 1.0) * dt
        f = r = u = 0.0
        for key in self.held:
            if key in FLY_KEYS:
                df, dr, du = FLY_KEYS[key]
                f, r, u = f + df, r + dr, u + du
            elif key in ROLL_KEYS:
                self.state = controls.roll_by(self.state, ROLL_KEYS[key] * dt)
        if f or r or u:
            self.state = controls.fly(self.state, f * speed, r * speed, u * speed)

    # ---------------------------------------------------------------------------- mouse
    def on_mouse_button(self, button: int, action: int) -> None:
        """Left drag orbits, right or middle drag pans."""
        if action == glfw.PRESS and self.drag is None:
            self.drag = button
            self.cursor = None
        elif action == glfw.RELEASE and button == self.drag:
            self.drag = None

    def on_cursor(self, x: float, y: float, window_height: Callable[[], int]) -> None:
        """The cursor moved to (x, y) (window coordinates, y down); ``window_height()`` gives
        the window's height in the same units, for panning."""
        if self.drag is not None and self.cursor is not None:
            dx, dy = x - self.cursor[0], y - self.cursor[1]
            if self.drag == glfw.MOUSE_BUTTON_LEFT:
                self.state = controls.orbit_drag(self.state, dx, dy)
            else:
                self.state = controls.pan(self.state, dx, dy, max(window_height(), 1))
        self.cursor = (x, y)

    def on_scroll(self, dy: float, cursor: tuple[float, float] | None = None,
                  window: tuple[int, int] | None = None) -> None:
        """Zoom by ``dy`` wheel steps towards the point under ``cursor`` (window coordinates of
        a ``window``-sized window; None: towards the centre)."""
        if cursor is None or window is None or min(window) <= 0:
            self.state = controls.zoom(self.state, dy)
        else:
            self.state = controls.zoom_at(self.state, dy, *cursor, *window)

    def drop_input(self) -> None:
        """Forget held keys and the drag (focus lost: their releases never report)."""
        self.held.clear()
        self.drag = None

    def cycle_up(self) -> str:
        """U: the next world up of +y, -y, +z, -z (from an up between them: +y); the orbit
        turns about it from here on, and R returns to the start view under it.  Returns the
        axis's name."""
        names = list(UP_AXES)
        now = [n for n in names if np.allclose(UP_AXES[n], self.state.up)]
        name = names[(names.index(now[0]) + 1) % len(names)] if now else names[0]
        self.state = replace(self.state, up=UP_AXES[name])
        self.home = replace(self.home, up=UP_AXES[name])
        return name

    # ---------------------------------------------------------------------------- cameras
    def step_camera(self, delta: int) -> str:
        """Jump to the next (``delta`` 1) or previous training camera; returns the status
        message."""
        if not self.cameras:
            return "no camera list (start with --camera cameras.json)"
        self.index = controls.step_index(self.index, len(self.cameras), delta)
        cam = self.cameras[self.index]
        self.state = controls.from_camera(cam, self.distance(cam), self.state.up)
        self.exact = (self.state, cam)
        return f"training camera {self.index + 1}/{len(self.cameras)}"

    def camera(self, width: int, height: int) -> Camera:
        """The current camera for a ``width`` x ``height`` window (world frame)."""
        if self.exact is not None and self.exact[0] == self.state:
            return controls.fit_camera(self.exact[1], width, height)
        return controls.to_camera(self.state, width, height)
