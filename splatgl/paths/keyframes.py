"""splatgl's own camera path file: keyframes interpolated to frames.

A JSON object::

    {
      "splatgl_path": 1,
      "width": 1280, "height": 720,
      "frames": 120,                      # or "fps": 30 with "seconds": 4
      "loop": false,                      # optional: close the path into a cycle
      "rotation": "squad",                # optional: "squad" (C1, default) or "slerp"
      "projection": "fisheye",            # optional: the camera model (default "perspective")
      "projection_fov": 200,              # optional: that model's field of view (its --fov)
      "keyframes": [
        {"eye": [x, y, z], "target": [x, y, z], "up": [0, -1, 0], "fov": 50, "time": 0.0},
        {"world_to_camera": [[...4x4...]], "fov": 50, "time": 2.0},
        ...
      ]
    }

Each keyframe gives a pose as a look-at (``eye``, ``target``, optional ``up``, default
``(0, -1, 0)``: world -y up, the COLMAP convention) or as a 4x4 ``world_to_camera`` (OpenCV
axes, rigid), and a vertical ``fov`` in degrees (default 50).  ``time`` (seconds, strictly
increasing) is optional: without it the keys are spread evenly over the path.  Positions follow
a Catmull-Rom spline (C1), rotations squad, fov linearly (:mod:`splatgl.paths.spline`).

The keys are perspective cameras.  With a ``projection`` other than ``perspective`` (a camera
model of :mod:`splatgl.cameras.registry`: a fisheye, a panorama, an orthographic view) each
frame's camera is that model at the frame's pose and size, as ``--projection NAME --fov
projection_fov`` re-projects a perspective camera (:func:`~splatgl.cameras.registry.retarget`:
an orthographic view keeps the perspective camera's focal length as pixels per world unit); the
viewer's K key records its lens views this way, so the path renders them without options.

``frames`` N samples the path evenly, the first and last frames on the first and last keys
(with ``loop``, N frames cover one cycle and the last key is not repeated); ``fps`` x
``seconds`` samples at ``k / fps``.  A frame that falls on a key reproduces that key's camera
exactly.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..cameras.camera import Camera
from ..cameras.poses import check_rigid_pose, look_at
from ..errors import CameraError
from ..cameras.json_fields import entries, matrix, number
from ..cameras.registry import model_class, names as model_names, retarget
from .spline import sample_poses

FORMAT_KEY = "splatgl_path"
FORMAT_VERSION = 1
DEFAULT_FOV = 50.0
DEFAULT_UP = (0.0, -1.0, 0.0)
#: The keys' own camera model (``projection`` left out).
PERSPECTIVE = model_names()[0]


@dataclass(frozen=True)
class Keyframe:
    """One key: ``world_to_camera`` (4, 4) float64 OpenCV axes, vertical ``fov`` degrees,
    ``time`` (seconds) or None."""

    world_to_camera: np.ndarray
    fov: float = DEFAULT_FOV
    time: float | None = None


def is_path_file(obj: object) -> bool:
    return isinstance(obj, dict) and FORMAT_KEY in obj


def _keyframe(path: Path, i: int, entry: object, height: int = 720) -> Keyframe:
    where = f"keyframes[{i}]: "
    if not isinstance(entry, dict):
        raise CameraError(f"{path}: {where}expected a JSON object")
    if "world_to_camera" in entry:
        w2c = matrix(path, where, entry, "world_to_camera", (4, 4))
        check_rigid_pose(w2c, f"{path}: {where}field 'world_to_camera'")
    elif "eye" in entry:
        eye = matrix(path, where, entry, "eye", (3,))
        target = matrix(path, where, entry, "target", (3,))
        up = matrix(path, where, entry, "up", (3,)) if "up" in entry else np.array(DEFAULT_UP)
        if np.allclose(eye, target):
            raise CameraError(f"{path}: {where}'eye' and 'target' coincide")
        try:
            w2c = look_at(eye, target, up)
        except CameraError as exc:
            raise CameraError(f"{path}: {where}{exc}") from None
    else:
        raise CameraError(f"{path}: {where}needs 'world_to_camera', or 'eye' and 'target'")
    fov = number(path, where, entry, "fov", DEFAULT_FOV)
    if not 0.0 < fov < 180.0:
        raise CameraError(f"{path}: {where}field 'fov' must be in (0, 180) degrees, got {fov}")
    time = number(path, where, entry, "time") if "time" in entry else None
    try:   # the key's numbers within what the renderers hold (a pose 1e20 away, a 1e-300 fov)
        Camera.from_fov(1, height, fov, w2c)
    except CameraError as exc:
        raise CameraError(f"{path}: {where}{exc}") from None
    return Keyframe(w2c, fov, time)


@dataclass(frozen=True)
class PathFile:
    """A parsed path file; :meth:`cameras` samples it."""

    width: int
    height: int
    keyframes: tuple[Keyframe, ...]
    frames: int | None = None
    fps: float | None = None
    seconds: float | None = None
    loop: bool = False
    rotation: str = "squad"
    #: The frames' camera model (None: perspective) and its field of view (None: the model's
    #: default), as ``--projection`` and ``--fov`` re-project the keys' perspective cameras.
    projection: str | None = None
    projection_fov: float | None = None

    def _key_times(self) -> np.ndarray:
        given = [k.time for k in self.keyframes]
        if all(t is not None for t in given):
            return np.array(given, np.float64)
        n = len(self.keyframes)
        span = self.seconds if self.seconds is not None else 1.0
        return np.arange(n) * (span / (n if self.loop else max(n - 1, 1)))

    def sample_times(self) -> np.ndarray:
        times = self._key_times()
        if self.frames is not None:
            n = self.frames
            if self.loop:
                period = times[-1] - times[0] + (times[1] - times[0] if len(times) > 1 else 1.0)
                return times[0] + period * np.arange(n) / n
            if n == 1:
                return times[:1].copy()
            # i / (n - 1) scaled, with the last frame exactly on the last key.
            out = times[0] + (times[-1] - times[0]) * (np.arange(n) / (n - 1))
            out[-1] = times[-1]
            return out
        return times[0] + np.arange(int(round(self.fps * self.seconds))) / self.fps

    def cameras(self) -> list[Camera]:
        """Every frame's camera, in order."""
        c2w = np.array([np.linalg.inv(k.world_to_camera) for k in self.keyframes])
        fovs = np.array([k.fov for k in self.keyframes])
        times = self._key_times()
        samples = self.sample_times()
        mats, fov = sample_poses(c2w, fovs, times, samples, self.loop, self.rotation)
        by_time = {float(t): k for t, k in zip(times, self.keyframes)}
        cams = []
        for m, f, t in zip(mats, fov, samples):
            key = by_time.get(float(t))  # on a key: its own matrix, not inv(inv(.))
            w2c = key.world_to_camera if key is not None else np.linalg.inv(m)
            cams.append(Camera.from_fov(self.width, self.height, float(f), w2c))
        if self.projection is not None:
            cams = [retarget(c, self.projection, self.projection_fov) for c in cams]
        return cams


def parse_path(path: Path, obj: dict) -> PathFile:
    version = obj.get(FORMAT_KEY)
    if version != FORMAT_VERSION:
        raise CameraError(f"{path}: field '{FORMAT_KEY}' must be {FORMAT_VERSION}, got {version!r}")
    w = number(path, "", obj, "width", 1280.0, positive=True)
    h = number(path, "", obj, "height", 720.0, positive=True)
    if not (w.is_integer() and h.is_integer()):
        raise CameraError(f"{path}: 'width' and 'height' must be whole numbers, got {w} x {h}")
    keys = tuple(_keyframe(path, i, e, int(h)) for i, e in enumerate(entries(path, obj, "keyframes")))
    timed = [k.time is not None for k in keys]
    if any(timed) and not all(timed):
        raise CameraError(f"{path}: give 'time' on every keyframe or on none")
    times = [k.time for k in keys]
    if all(timed) and any(b <= a for a, b in zip(times, times[1:])):
        raise CameraError(f"{path}: keyframe times must increase strictly, got {times}")
    loop = obj.get("loop", False)
    if not isinstance(loop, bool):
        raise CameraError(f"{path}: field 'loop' must be true or false, got {loop!r}")
    if loop and all(timed):
        raise CameraError(f"{path}: a looping path spreads its keys evenly; remove the 'time' fields")
    rotation = obj.get("rotation", "squad")
    if rotation not in ("squad", "slerp"):
        raise CameraError(f"{path}: field 'rotation' must be 'squad' or 'slerp', got {rotation!r}")
    projection, projection_fov = _projection(path, obj)
    frames = fps = seconds = None
    if "frames" in obj:
        frames = number(path, "", obj, "frames", positive=True)
        if not frames.is_integer():
            raise CameraError(f"{path}: field 'frames' must be a whole number, got {frames}")
        frames = int(frames)
        seconds = number(path, "", obj, "seconds", positive=True) if "seconds" in obj else None
    elif "fps" in obj:
        fps = number(path, "", obj, "fps", positive=True)
        seconds = number(path, "", obj, "seconds", positive=True)
        if int(round(fps * seconds)) < 1:
            raise CameraError(f"{path}: fps x seconds = {fps * seconds:g} gives no frame")
    else:
        raise CameraError(f"{path}: needs 'frames', or 'fps' and 'seconds'")
    return PathFile(int(w), int(h), keys, frames, fps, seconds, loop, rotation, projection,
                    projection_fov)


def _projection(path: Path, obj: dict) -> tuple[str | None, float | None]:
    """The ``projection`` (None: perspective) and ``projection_fov`` fields, checked."""
    name = obj.get("projection", PERSPECTIVE)
    try:
        cls = model_class(name, "field 'projection'")
    except CameraError as exc:
        raise CameraError(f"{path}: {exc}") from None
    if "projection_fov" not in obj:
        return (None if cls.name == PERSPECTIVE else cls.name), None
    fov = number(path, "", obj, "projection_fov")
    if cls.no_fov or cls.name == PERSPECTIVE:
        why = cls.no_fov or "the keys' own 'fov' is a perspective camera's"
        raise CameraError(f"{path}: field 'projection_fov' does not apply to projection "
                          f"'{cls.name}': {why}")
    lo, hi, closed = cls.fov_range()
    if not (lo < fov <= hi if closed else lo < fov < hi):
        raise CameraError(f"{path}: field 'projection_fov' of a {cls.name} must be in ({lo:g}, "
                          f"{hi:g}{']' if closed else ')'} degrees, got {fov:g}")
    return cls.name, fov


def path_json(cameras: list[Camera], frames: int | None = None, loop: bool = False,
              fps: float | None = None, look_at_target: np.ndarray | None = None,
              up: np.ndarray | None = None) -> dict:
    """A path file object with one keyframe per camera (``world_to_camera`` matrices, or
    eye/target/up look-ats when ``look_at_target`` is given), sampled to ``frames`` (default:
    one frame per key, reproducing the cameras exactly)."""
    c0 = cameras[0]
    keys = []
    for c in cameras:
        fov = float(np.degrees(2.0 * np.arctan(0.5 * c.height / c.fy)))
        if look_at_target is not None:
            keys.append({"eye": c.center.tolist(), "target": list(map(float, look_at_target)),
                         "up": list(map(float, up if up is not None else DEFAULT_UP)), "fov": fov})
        else:
            keys.append({"world_to_camera": c.world_to_camera.tolist(), "fov": fov})
    obj = {FORMAT_KEY: FORMAT_VERSION, "width": c0.width, "height": c0.height,
           "frames": frames if frames is not None else len(cameras)}
    if fps is not None:
        obj["fps"] = fps  # the video frame rate; 'frames' still decides the count
    if loop:
        obj["loop"] = True
    obj["keyframes"] = keys
    return obj


def write_path(path: Path, obj: dict) -> None:
    from ..writing.atomic import atomic_write_text

    atomic_write_text(Path(path), json.dumps(obj, indent=1) + "\n")
