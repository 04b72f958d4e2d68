"""Camera path generators: orbit a scene, spiral or ellipse through training cameras, and
interpolate between chosen cameras.  All return lists of :class:`~splatgl.cameras.camera.Camera`
(OpenCV axes, vertical fov in degrees where asked).
"""

from __future__ import annotations

import math

import numpy as np

from ..cameras.camera import Camera
from ..cameras.poses import look_at, orbit as orbit_pose
from ..errors import CameraError
from ..cameras.framing import DEFAULT_ELEVATION, DEFAULT_FOV_Y, default_camera
from ..scene.splats import Scene


def orbit(scene: Scene, frames: int = 120, width: int = 1280, height: int = 720,
          fov: float = DEFAULT_FOV_Y, elevation: float = DEFAULT_ELEVATION,
          radius: float | None = None, up=(0.0, -1.0, 0.0)) -> list[Camera]:
    """``frames`` cameras on a circle around the scene's robust centre (the middle of its
    1st-99th percentile box), looking at it, ``elevation`` degrees above the plane normal to
    ``up``.  ``radius`` defaults to :func:`splatgl.api.default_camera`'s framing distance;
    frame 0 is the default camera's view (azimuth 180), and the path turns a full circle
    without repeating frame 0 at the end."""
    if frames < 1:
        raise CameraError(f"orbit: frames must be at least 1, got {frames}")
    lo, hi = scene.robust_bounds
    centre = 0.5 * (lo + hi)
    if radius is None:
        radius = float(np.linalg.norm(default_camera(scene, width, height, fov).center - centre))
    if not radius > 0:
        raise CameraError(f"orbit: radius must be positive, got {radius}")
    return [Camera.from_fov(width, height, fov,
                            orbit_pose(centre, radius, 180.0 + 360.0 * k / frames, elevation, up))
            for k in range(frames)]


def focus_point(cameras: list[Camera]) -> np.ndarray:
    """(3,) the point nearest (least squares) to every camera's optical axis: where a set of
    inward-looking training cameras converge."""
    a = np.zeros((3, 3))
    b = np.zeros(3)
    for c in cameras:
        d = c.rotation[2]  # camera +z (forward) in world coordinates
        m = np.eye(3) - np.outer(d, d)
        a += m
        b += m @ c.center
    if abs(np.linalg.det(a)) < 1e-9:  # all axes parallel: look ahead of the mean camera
        mean_d = np.mean([c.rotation[2] for c in cameras], axis=0)
        return np.mean([c.center for c in cameras], axis=0) + mean_d
    return np.linalg.solve(a, b)


def _mean_frame(cameras: list[Camera]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(mean centre, mean up (world, unit), (3, 3) mean camera-to-world rotation)."""
    centres = np.array([c.center for c in cameras])
    up = -np.mean([c.rotation[1] for c in cameras], axis=0)  # camera -y is image-up
    forward = np.mean([c.rotation[2] for c in cameras], axis=0)
    if np.linalg.norm(up) < 1e-9 or np.linalg.norm(forward) < 1e-9:
        raise CameraError("the cameras' mean up or viewing direction vanishes; cannot fit a path")
    up /= np.linalg.norm(up)
    rot = look_at(np.zeros(3), forward, up)[:3, :3].T  # columns: camera axes in world
    return centres.mean(axis=0), up, rot


def spiral(cameras: list[Camera], frames: int = 120, rotations: float = 2.0,
           z_rate: float = 0.5, percentile: float = 90.0) -> list[Camera]:
    """The forward-facing spiral of the NeRF/3DGS LLFF videos: around the mean camera, with
    radii the ``percentile`` of the cameras' offsets along each of its axes, ``rotations`` turns,
    looking at :func:`focus_point`.  Intrinsics are the first camera's."""
    if len(cameras) < 2:
        raise CameraError("spiral needs at least 2 cameras")
    centre, up, rot = _mean_frame(cameras)
    local = (np.array([c.center for c in cameras]) - centre) @ rot
    radii = np.percentile(np.abs(local), percentile, axis=0)
    target = focus_point(cameras)
    out = []
    for theta in np.linspace(0.0, 2.0 * math.pi * rotations, frames, endpoint=False):
        offset = np.array([math.cos(theta), -math.sin(theta), -math.sin(theta * z_rate)]) * radii
        eye = centre + rot @ offset
        out.append(cameras[0].with_pose(look_at(eye, target, up)))
    return out


def ellipse(cameras: list[Camera], frames: int = 120, percentile: float = 90.0) -> list[Camera]:
    """An ellipse around the scene through the training cameras (nerfstudio/Mip-NeRF 360 video
    path): in the plane normal to the cameras' mean up, centred under :func:`focus_point`,
    axes along the principal directions of the camera centres, radii their ``percentile``
    extent, at the cameras' mean height, always looking at the focus point.  Intrinsics are the
    first camera's."""
    if len(cameras) < 3:
        raise CameraError("ellipse needs at least 3 cameras")
    _, up, _ = _mean_frame(cameras)
    target = focus_point(cameras)
    centres = np.array([c.center for c in cameras]) - target
    height = float(np.mean(centres @ up))
    flat = centres - np.outer(centres @ up, up)
    _, _, vt = np.linalg.svd(flat, full_matrices=False)
    a = vt[0] - up * (vt[0] @ up)
    a /= np.linalg.norm(a)
    b = np.cross(up, a)
    ra, rb = (np.percentile(np.abs(flat @ axis), percentile) for axis in (a, b))
    if not (ra > 0 and rb > 0):
        raise CameraError("the cameras' centres do not spread around the scene; cannot fit an ellipse")
    out = []
    for theta in np.linspace(0.0, 2.0 * math.pi, frames, endpoint=False):
        eye = target + height * up + ra * math.cos(theta) * a + rb * math.sin(theta) * b
        out.append(cameras[0].with_pose(look_at(eye, target, up)))
    return out


def interpolate(cameras: list[Camera], frames: int = 120, loop: bool = False,
                rotation: str = "squad") -> list[Camera]:
    """``frames`` cameras along a smooth path through ``cameras`` (keys spread evenly):
    Catmull-Rom positions, squad rotations, vertical fov linearly; the first camera's size."""
    from .keyframes import Keyframe, PathFile

    if not cameras:
        raise CameraError("interpolate needs at least 1 camera")
    c0 = cameras[0]
    keys = tuple(Keyframe(c.world_to_camera, math.degrees(2.0 * math.atan(0.5 * c.height / c.fy)))
                 for c in cameras)
    return PathFile(c0.width, c0.height, keys, frames=frames, loop=loop, rotation=rotation).cameras()
