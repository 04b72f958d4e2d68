"""NeRF / nerfstudio ``transforms.json`` (Blender synthetic, instant-ngp, nerfstudio data).

Axes: each frame's ``transform_matrix`` is camera-to-world in OpenGL camera axes (+x right,
+y up, +z backward, the camera looks along -z).  splatgl's cameras use OpenCV axes, so the
camera's y and z columns flip: ``c2w_cv = c2w_gl diag(1, -1, -1, 1)``,
``world_to_camera = c2w_cv^-1``.  The world frame is taken as it is (no re-centring).

Intrinsics, per frame or at the top level (per-frame values win): ``fl_x``/``fl_y``/``cx``/``cy``
with ``w``/``h``, or ``camera_angle_x`` (horizontal fov, radians; square pixels, principal point
at the image centre) with the size from ``w``/``h`` or the image file.  ``camera_model`` (default
``OPENCV``) names the camera model, whose own fields (``k1``, ``p1``, ...) the model reads: the
camera models' table :data:`splatgl.cameras.registry.TRANSFORMS` (the pinhole's OPENCV,
PINHOLE and SIMPLE_PINHOLE without distortion, the fisheye's OPENCV_FISHEYE, ...); any other
``camera_model`` is rejected by name.  Writing uses each model's ``to_transforms``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..cameras.camera import Camera
from ..cameras.poses import check_rigid_pose
from ..cameras.registry import TRANSFORMS
from ..errors import CameraError
from ..cameras.json_fields import entries, matrix, number, read_json
from .named_camera import NamedCamera

#: OpenGL camera axes -> OpenCV camera axes (flip y and z), applied on the right of c2w.
GL_TO_CV = np.diag([1.0, -1.0, -1.0, 1.0])
_IMAGE_EXTS = ("", ".png", ".jpg", ".jpeg", ".JPG", ".PNG", ".exr")


def is_transforms(obj: object) -> bool:
    return isinstance(obj, dict) and isinstance(obj.get("frames"), list) and \
        any(isinstance(f, dict) and "transform_matrix" in f for f in obj["frames"])


def find_image(root: Path, name: str) -> Path | None:
    """The photograph a frame's ``file_path`` names (Blender files omit the extension)."""
    for ext in _IMAGE_EXTS:
        cand = root / (name + ext)
        if cand.is_file():
            return cand
    return None


def image_size(path: Path) -> tuple[int, int]:
    """(width, height) from an image file's header."""
    import OpenImageIO as oiio

    from ..imagefiles.images import quiet_image_library

    with quiet_image_library():
        inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise CameraError(f"{path}: cannot read image header ({oiio.geterror()})")
    try:
        return inp.spec().width, inp.spec().height
    finally:
        inp.close()


def _intrinsics(path: Path, where: str, frame: dict, top: dict, image: Path | None):
    def get(key):
        if key in frame:
            return number(path, where, frame, key)
        if key in top:
            return number(path, "", top, key)
        return None

    name = frame.get("camera_model", top.get("camera_model", "OPENCV"))
    cls = TRANSFORMS.get(name) if isinstance(name, str) else None
    if cls is None:
        raise CameraError(f"{path}: {where}camera_model {name!r} is not supported "
                          f"(supported: {', '.join(TRANSFORMS)})")
    fields = {key: get(key) for key in cls.transforms_fields}
    try:
        model = cls.from_transforms(name, fields)
    except CameraError as exc:
        raise CameraError(f"{path}: {where}{exc}") from None
    w, h = get("w"), get("h")
    if w is None or h is None:
        if image is None:
            raise CameraError(f"{path}: {where}no 'w'/'h' given and the image file was not found")
        w, h = image_size(image)
    fx, fy = get("fl_x"), get("fl_y")
    if fx is None and fy is None:
        angle_x = get("camera_angle_x")
        if angle_x is None:
            raise CameraError(f"{path}: {where}needs 'fl_x'/'fl_y' or 'camera_angle_x'")
        if not 0.0 < angle_x < math.pi:
            raise CameraError(f"{path}: {where}field 'camera_angle_x' must be in (0, pi) radians, got {angle_x}")
        fx = 0.5 * w / math.tan(0.5 * angle_x)
        angle_y = get("camera_angle_y")
        fy = 0.5 * h / math.tan(0.5 * angle_y) if angle_y is not None else fx
    fx = fx if fx is not None else fy
    fy = fy if fy is not None else fx
    cx, cy = get("cx"), get("cy")
    return w, h, fx, fy, (w / 2.0 if cx is None else cx), (h / 2.0 if cy is None else cy), model


def load_transforms(path: Path, obj: dict | None = None) -> list[NamedCamera]:
    """The views of a ``transforms.json`` in file order; photographs looked up beside it."""
    path = Path(path)
    obj = read_json(path) if obj is None else obj
    if not isinstance(obj, dict):
        raise CameraError(f"{path}: expected a JSON object with 'frames'")
    frames = entries(path, obj, "frames")
    views = []
    for i, frame in enumerate(frames):
        where = f"frame {i}: "
        if not isinstance(frame, dict):
            raise CameraError(f"{path}: {where}expected a JSON object")
        c2w = matrix(path, where, frame, "transform_matrix", (4, 4))
        check_rigid_pose(c2w, f"{path}: {where}field 'transform_matrix'")
        name = str(frame.get("file_path", f"frame_{i:05d}"))
        image = find_image(path.parent, name)
        w, h, fx, fy, cx, cy, model = _intrinsics(path, where, frame, obj, image)
        w2c = np.linalg.inv(c2w @ GL_TO_CV)
        try:
            camera = Camera(int(round(w)), int(round(h)), fx, fy, cx, cy, w2c, model)
        except CameraError as exc:
            raise CameraError(f"{path}: {where}{exc}") from None
        views.append(NamedCamera(name, camera, image))
    return views


def transforms_json(views: list[NamedCamera]) -> dict:
    """The ``transforms.json`` object of ``views`` (per-frame fl_x/fl_y/cx/cy/w/h, and the
    camera model's own fields where it is not the file's plain ``OPENCV``:
    :meth:`~splatgl.cameras.model.CameraModel.to_transforms`, which raises CameraError for a
    scene transforms.json cannot hold)."""
    frames = []
    for v in views:
        c = v.camera
        fields = c.model.to_transforms()
        own = {} if fields == {"camera_model": "OPENCV"} else fields
        frames.append({"file_path": v.name, "transform_matrix": (np.linalg.inv(c.world_to_camera) @ GL_TO_CV).tolist(),
                       "fl_x": c.fx, "fl_y": c.fy, "cx": c.cx, "cy": c.cy, "w": c.width, "h": c.height,
                       **own})
    return {"camera_model": "OPENCV", "frames": frames}
