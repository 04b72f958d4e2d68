"""Camera files: splatgl's single-camera JSON and the cameras.json of 3DGS training output.

(a) Single camera: ``{"width", "height", "fx", "fy", "cx", "cy", "world_to_camera": 4x4
    row-major, optional "projection": "perspective" | "orthographic" | "fisheye" | "opencv" |
    "equirectangular"}`` (orthographic fx, fy in pixels per world unit; fisheye fx, fy in pixels
    per radian with optional "distortion": [k1, k2, k3, k4]; opencv with optional "distortion":
    OpenCV's distCoeffs, 4, 5 or 8 numbers; equirectangular may omit the
    intrinsics for a full panorama, and may give "ods_eye" for one eye of a stereo pair), or with ``"frustum": {"left", "right", "top", "bottom", "near",
    "far"}`` in place of the intrinsics.
(b) 3DGS ``cameras.json``: a list of ``{"width", "height", "position", "rotation", "fx", "fy",
    ...}`` where ``rotation`` is camera-to-world (3x3, rows as stored) and ``position`` the camera
    centre; the principal point is the image centre.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np

from .camera import Camera
from .poses import check_rigid_pose
from .registry import MODELS, adapt_camera, model_class
from ..errors import CameraError, require
from .json_fields import matrix, read_json


def _number(path: Path, where: str, obj: dict, key: str) -> float:
    if key not in obj:
        raise CameraError(f"{path}: {where}missing field '{key}'")
    value = obj[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise CameraError(f"{path}: {where}field '{key}' must be a finite number, got {value!r}")
    return float(value)


def _matrix(path: Path, where: str, obj: dict, key: str, shape: tuple[int, ...]) -> np.ndarray:
    """Field ``key`` as a float64 array of ``shape``; the error says what is wrong with it."""
    return matrix(path, where, obj, key, shape, flat=False)


def _pose(path: Path, where: str, obj: dict) -> np.ndarray:
    """The rigid ``world_to_camera`` of a single-camera object (4x4, checked)."""
    w2c = _matrix(path, where, obj, "world_to_camera", (4, 4))
    return check_rigid_pose(w2c, f"{path}: {where}field 'world_to_camera'")


def _camera_from_frustum(obj: dict, path: Path) -> Camera:
    frustum = obj["frustum"]
    if not isinstance(frustum, dict):
        raise CameraError(f"{path}: field 'frustum' must be an object with left, right, top, bottom, near")
    where = "frustum: "
    b = {k: _number(path, where, frustum, k) for k in ("left", "right", "top", "bottom", "near")}
    far = _number(path, where, frustum, "far") if "far" in frustum else None
    w, h = _number(path, "", obj, "width"), _number(path, "", obj, "height")
    w2c = _pose(path, "", obj)
    try:
        return Camera.from_frustum(int(w), int(h), b["left"], b["right"], b["top"], b["bottom"],
                                   b["near"], far, w2c)
    except CameraError as exc:
        raise CameraError(f"{path}: {exc}") from None


#: What to say to a camera file giving a model's field under a projection that ignores it.
_FIELD_HINTS = {"distortion": 'use "projection": "opencv" for OpenCV\'s distCoeffs (k1 k2 p1 p2 '
                              '[k3 [k4 k5 k6]]) or "fisheye" for its k1 k2 k3 k4'}


def _is_zero(value) -> bool:
    """A number 0, or a list of them: a field that changes nothing whichever model reads it."""
    values = value if isinstance(value, list) else [value]
    return all(isinstance(v, (int, float)) and not isinstance(v, bool) and v == 0 for v in values)


def _check_foreign_fields(obj: dict, cls, path: Path) -> None:
    """Refuse a field only other projections read (a ``"distortion"`` list on a perspective
    camera rendered undistorted without a word); zeros change nothing and pass."""
    for key in dict.fromkeys(k for m in MODELS.values() for k in m.json_fields):
        if key in obj and key not in cls.json_fields and not _is_zero(obj[key]):
            readers = [m.name for m in MODELS.values() if key in m.json_fields]
            given = (f'"projection": "{cls.name}"' if "projection" in obj
                     else f'the default projection "{cls.name}"')
            hint = _FIELD_HINTS.get(key, "use " + " or ".join(f'"projection": "{n}"' for n in readers))
            raise CameraError(f"{path}: field '{key}' would be ignored: {given} does not read it; "
                              f"{hint}, or remove the field")


def camera_from_json(obj: dict, path: Path = Path("<camera>")) -> Camera:
    """A camera from the single-camera JSON object (form (a)).

    Instead of ``fx, fy, cx, cy`` the object may give ``"frustum": {"left", "right", "top",
    "bottom", "near", optional "far"}`` (OpenGL-style bounds at the near plane, y up), which
    maps to exactly the same pixels as the equivalent intrinsics.
    """
    if not isinstance(obj, dict):
        raise CameraError(f"{path}: expected a JSON object with width, height, fx, fy, cx, cy, world_to_camera")
    if "frustum" in obj:
        return _camera_from_frustum(obj, path)
    try:
        cls = model_class(obj.get("projection", "perspective"), "field 'projection'")
    except CameraError as exc:
        raise CameraError(f"{path}: {exc}") from None
    _check_foreign_fields(obj, cls, path)
    keys = ("width", "height", "fx", "fy", "cx", "cy")
    w2c = _pose(path, "", obj)
    model = cls.from_json(obj, path)
    if not any(k in obj for k in keys[2:]) and cls.intrinsics_optional:   # e.g. a full panorama
        w, h = _number(path, "", obj, "width"), _number(path, "", obj, "height")
        vals = dict(zip(keys, (w, h, *cls.intrinsics(w, h, None)[:4])))
    else:
        vals = {k: _number(path, "", obj, k) for k in keys}
    try:
        return Camera(int(vals["width"]) if vals["width"].is_integer() else vals["width"],
                      int(vals["height"]) if vals["height"].is_integer() else vals["height"],
                      vals["fx"], vals["fy"], vals["cx"], vals["cy"], w2c, model)
    except CameraError as exc:
        raise CameraError(f"{path}: {exc}") from None


def camera_from_3dgs(entry: dict, path: Path, index: int) -> Camera:
    """A camera from one entry of a 3DGS cameras.json (form (b))."""
    where = f"camera {index}: "
    if not isinstance(entry, dict):
        raise CameraError(f"{path}: {where}expected a JSON object")
    w, h = _number(path, where, entry, "width"), _number(path, where, entry, "height")
    fx, fy = _number(path, where, entry, "fx"), _number(path, where, entry, "fy")
    c2w_rot = _matrix(path, where, entry, "rotation", (3, 3))
    centre = _matrix(path, where, entry, "position", (3,))
    check_rigid_pose(c2w_rot, f"{path}: {where}field 'rotation'")
    w2c = np.eye(4)
    w2c[:3, :3] = c2w_rot.T
    w2c[:3, 3] = -c2w_rot.T @ centre
    try:
        return Camera(int(w), int(h), fx, fy, w / 2.0, h / 2.0, w2c)
    except CameraError as exc:
        raise CameraError(f"{path}: {where}{exc}") from None


def load_cameras(path: str | Path) -> list[Camera]:
    """Every camera in a file of either form (a list of one for form (a))."""
    path = Path(path)
    obj = read_json(path, "camera file")
    if isinstance(obj, list):
        if not obj:
            raise CameraError(f"{path}: the camera list is empty")
        return [camera_from_3dgs(entry, path, i) for i, entry in enumerate(obj)]
    return [camera_from_json(obj, path)]


def load_camera(path: str | Path, index: int = 0, *, width: int | None = None,
                height: int | None = None, projection: str | None = None,
                fov_degrees: float | None = None) -> Camera:
    """Camera ``index`` of a camera file (index 0 for a single-camera JSON).

    ``width``, ``height``, ``projection`` and ``fov_degrees`` adapt it as ``--camera`` with
    ``--width``, ``--height``, ``--projection`` and ``--fov`` do (:func:`splatgl.cameras.registry.adapt_camera`):
    the file's own intrinsics scale keeping its aspect; another projection or a field of view
    keeps only its pose, at any size (an equirectangular panorama defaults to 2:1).
    """
    cams = load_cameras(path)
    if not -len(cams) <= index < len(cams):
        raise CameraError(f"{path}: camera index {index} out of range (the file has {len(cams)} camera(s))")
    return adapt_camera(cams[index], width, height, projection, fov_degrees, str(path))


def save_camera(path: str | Path, camera: Camera) -> None:
    """Write the single-camera JSON form (a) of ``camera``, atomically (a failed write raises
    one line naming ``path`` and leaves the old file, if any)."""
    from ..writing.atomic import atomic_write_text

    require(path, (str, os.PathLike), "save_camera", "path",
            "a file path (a str or a pathlib.Path; the camera goes second)")
    require(camera, Camera, "save_camera", "camera", "a splatgl Camera")
    atomic_write_text(path, json.dumps(camera.to_json(), indent=2) + "\n")
