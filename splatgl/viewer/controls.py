"""Pure input -> camera functions of the viewer: no window, no OpenGL, no clock.

The view is a frozen :class:`ViewState`: the camera orbits ``target`` at ``distance`` with
``yaw`` (about the world ``up``) and ``pitch`` (towards ``up``) in degrees, exactly as
:func:`splatgl.cameras.poses.orbit` places it, then rolls by ``roll`` degrees about its own viewing
axis.  Every function returns a new state; :func:`to_camera` turns one into a
:class:`~splatgl.cameras.camera.Camera` for a window of a given size (square pixels, vertical field of
view ``fov_y``).  Pixel deltas are in window coordinates (x right, y down).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ..cameras.camera import Camera
from ..cameras.poses import look_at, orbit

#: Pitch is kept inside (-PITCH_LIMIT, PITCH_LIMIT) degrees so ``look_at`` never degenerates.
PITCH_LIMIT = 89.0
#: Field-of-view limits, degrees.
FOV_RANGE = (5.0, 150.0)
#: Orbit speed, degrees per dragged pixel.
ORBIT_DEGREES_PER_PIXEL = 0.3
#: Distance factor of one wheel step (wheel up moves closer).
ZOOM_FACTOR = 1.15
#: Smallest orbit distance, as a fraction of the home distance is up to the caller; absolute:
MIN_DISTANCE = 1e-6
#: Largest orbit distance: well inside the camera's reach (splatgl.cameras.poses.MAX_CAMERA_VALUE,
#: what float32 arithmetic holds), so no number of wheel steps makes an unrenderable camera.
MAX_DISTANCE = 1e15


@dataclass(frozen=True)
class ViewState:
    """An orbit camera: what the mouse and keyboard change.

    Attributes:
        target: (3,) world point the camera orbits and looks at (world units).
        distance: eye-to-target distance (world units, > 0).
        yaw, pitch, roll: degrees (see the module docstring).
        fov_y: vertical field of view, degrees.
        up: (3,) world direction that appears up on screen; (0, -1, 0) suits COLMAP scenes.
    """

    target: tuple[float, float, float]
    distance: float
    yaw: float = 180.0
    pitch: float = 20.0
    roll: float = 0.0
    fov_y: float = 50.0
    up: tuple[float, float, float] = (0.0, -1.0, 0.0)

    def __post_init__(self) -> None:
        object.__setattr__(self, "target", tuple(float(v) for v in self.target))
        object.__setattr__(self, "up", tuple(float(v) for v in self.up))
        object.__setattr__(self, "distance", min(max(float(self.distance), MIN_DISTANCE), MAX_DISTANCE))
        object.__setattr__(self, "pitch", float(np.clip(self.pitch, -PITCH_LIMIT, PITCH_LIMIT)))
        object.__setattr__(self, "yaw", float(self.yaw) % 360.0)
        object.__setattr__(self, "roll", (float(self.roll) + 180.0) % 360.0 - 180.0)
        object.__setattr__(self, "fov_y", float(np.clip(self.fov_y, *FOV_RANGE)))


# ------------------------------------------------------------------------------- geometry
def _roll_matrix(degrees: float) -> np.ndarray:
    """Rotation about the camera's +z (viewing) axis, in camera coordinates."""
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def world_to_camera(state: ViewState) -> np.ndarray:
    """(4, 4) float64 world-to-camera matrix (OpenCV axes) of ``state``."""
    m = orbit(np.array(state.target), state.distance, state.yaw, state.pitch, np.array(state.up))
    if state.roll:
        r = _roll_matrix(state.roll)
        m[:3, :3] = r @ m[:3, :3]
        m[:3, 3] = r @ m[:3, 3]
    return m


def axes(state: ViewState) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World-space unit vectors (right, down, forward) of the camera (image x, image y, view)."""
    r = world_to_camera(state)[:3, :3]
    return r[0].copy(), r[1].copy(), r[2].copy()


def eye(state: ViewState) -> np.ndarray:
    """(3,) camera centre in world units."""
    return np.array(state.target) - state.distance * axes(state)[2]


def to_camera(state: ViewState, width: int, height: int) -> Camera:
    """The camera of ``state`` for a ``width`` x ``height`` pixel image (square pixels)."""
    return Camera.from_fov(width, height, state.fov_y, world_to_camera(state))


def fit_camera(camera: Camera, width: int, height: int) -> Camera:
    """``camera`` (pose and intrinsics, off-centre principal point and fx != fy included) shown
    in a ``width`` x ``height`` window: scaled by the height ratio, its frame centred
    horizontally.  At the camera's own size it is the camera itself."""
    s = height / camera.height
    return Camera(width, height, camera.fx * s, camera.fy * s,
                  camera.cx * s + 0.5 * (width - camera.width * s), camera.cy * s,
                  camera.world_to_camera, camera.model)


def from_camera(camera: Camera, distance: float, up=(0.0, -1.0, 0.0)) -> ViewState:
    """The state that reproduces ``camera``'s pose, orbiting a point ``distance`` ahead of it.

    The field of view is the camera's vertical one (``2 atan(H / (2 fy))``); a principal point
    off centre or non-square pixels are not kept (the window has its own size).
    """
    up = np.asarray(up, np.float64) / np.linalg.norm(up)
    r = camera.rotation / camera.scale
    forward = r[2]
    centre = camera.center
    target = centre + distance * forward
    back = -forward  # unit direction target -> eye, as orbit() parameterises it
    pitch = math.degrees(math.asin(float(np.clip(back @ up, -1.0, 1.0))))
    ref = np.array([0.0, 0.0, 1.0]) if abs(up[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    a = ref - up * (ref @ up)
    a /= np.linalg.norm(a)
    b = np.cross(up, a)
    yaw = math.degrees(math.atan2(float(back @ b), float(back @ a)))
    unrolled = look_at(centre, target, up)[:3, :3]
    rel = r @ unrolled.T  # = roll matrix
    roll = math.degrees(math.atan2(rel[1, 0], rel[0, 0]))
    fov_y = math.degrees(2.0 * math.atan(camera.height / (2.0 * camera.fy)))
    return ViewState(tuple(target), distance, yaw, pitch, roll, fov_y, tuple(up))


# ------------------------------------------------------------------------------- inputs
def orbit_drag(state: ViewState, dx: float, dy: float,
               degrees_per_pixel: float = ORBIT_DEGREES_PER_PIXEL) -> ViewState:
    """Left drag: turn about the target (the distance to it is unchanged).

    Dragging right turns the scene to the right; dragging down lifts the camera.
    """
    return replace(state, yaw=state.yaw - dx * degrees_per_pixel,
                   pitch=state.pitch + dy * degrees_per_pixel)


def world_per_pixel(state: ViewState, height: int) -> float:
    """World units one pixel spans on the plane through the target facing the camera."""
    return 2.0 * state.distance * math.tan(math.radians(state.fov_y) / 2.0) / max(height, 1)


def pan(state: ViewState, dx: float, dy: float, height: int) -> ViewState:
    """Right/middle drag: move the target in the camera's image plane so that the point under
    the cursor follows it (``dx``, ``dy`` window pixels; ``height`` the window height)."""
    right, down, _ = axes(state)
    s = world_per_pixel(state, height)
    target = np.array(state.target) - right * dx * s - down * dy * s
    return replace(state, target=tuple(target))


def zoom(state: ViewState, steps: float, factor: float = ZOOM_FACTOR) -> ViewState:
    """Wheel: the distance is divided by ``factor`` per step (positive steps move closer)."""
    return replace(state, distance=state.distance * factor ** (-steps))


def zoom_at(state: ViewState, steps: float, x: float, y: float, width: int, height: int,
            factor: float = ZOOM_FACTOR) -> ViewState:
    """Wheel over window point (``x``, ``y``) of a ``width`` x ``height`` window (y down): zoom
    as :func:`zoom`, moving the target towards the point under the cursor on the plane through
    the target, so that point stays under the cursor (the window's centre: :func:`zoom`)."""
    right, down, _ = axes(state)
    s = world_per_pixel(state, height)
    under = np.array(state.target) + right * (x - 0.5 * width) * s + down * (y - 0.5 * height) * s
    keep = factor ** (-steps)          # the new distance's share of the old one
    target = under + (np.array(state.target) - under) * keep
    return replace(state, target=tuple(target), distance=state.distance * keep)


def fly(state: ViewState, forward: float = 0.0, right: float = 0.0, up: float = 0.0) -> ViewState:
    """Move eye and target together along the view axes by the given world distances.

    ``up`` is the image's up direction (the camera's -y), so rolls are respected.
    """
    r, d, f = axes(state)
    move = f * forward + r * right - d * up
    return replace(state, target=tuple(np.array(state.target) + move))


def roll_by(state: ViewState, degrees: float) -> ViewState:
    """Turn the image about the viewing axis (positive turns the picture clockwise)."""
    return replace(state, roll=state.roll + degrees)


def change_fov(state: ViewState, degrees: float) -> ViewState:
    """Widen (positive) or narrow the vertical field of view, within :data:`FOV_RANGE`."""
    return replace(state, fov_y=state.fov_y + degrees)


def reset(state: ViewState, home: ViewState) -> ViewState:
    """R: back to the home view (the start view)."""
    return home


def step_index(index: int, count: int, delta: int) -> int:
    """Camera stepping: the index ``delta`` places on from ``index``, wrapping around."""
    if count <= 0:
        raise ValueError("no cameras to step through")
    return (index + delta) % count


def fly_speed(home: ViewState) -> float:
    """World units per second of WASD flight: half the home distance per second."""
    return 0.5 * home.distance
