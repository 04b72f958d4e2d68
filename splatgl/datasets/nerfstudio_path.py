"""nerfstudio ``camera_path.json``, as its viewer exports for ``ns-render camera-path``.

Read: ``render_width``, ``render_height``, ``fps``, ``seconds``, ``camera_type`` (only
``perspective``), and ``camera_path``: one entry per output frame (the viewer has already
interpolated its keyframes) with ``camera_to_world`` (16 numbers, row-major 4x4, or 12 for
3x4) and ``fov`` (vertical, degrees).  Axes as in nerfstudio: camera-to-world in OpenGL camera
axes (+x right, +y up, looking along -z), so ``c2w_cv = c2w diag(1, -1, -1, 1)``.  Poses are
used in the scene's own frame (nerfstudio's dataparser scale/transform is not undone).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..cameras.camera import Camera
from ..cameras.poses import check_rigid_pose
from ..errors import CameraError
from ..cameras.json_fields import entries, matrix, number
from .nerf import GL_TO_CV
from .named_camera import NamedCamera


def is_camera_path(obj: object) -> bool:
    return isinstance(obj, dict) and "camera_path" in obj


def frame_rate(obj: dict) -> float | None:
    fps = obj.get("fps")
    return float(fps) if isinstance(fps, (int, float)) and not isinstance(fps, bool) and fps > 0 else None


def load_camera_path(path: Path, obj: dict) -> list[NamedCamera]:
    path = Path(path)
    kind = obj.get("camera_type", "perspective")
    if kind != "perspective":
        raise CameraError(f"{path}: field 'camera_type' is {kind!r}; splatgl renders 'perspective' only")
    w = number(path, "", obj, "render_width", positive=True)
    h = number(path, "", obj, "render_height", positive=True)
    views = []
    for i, entry in enumerate(entries(path, obj, "camera_path")):
        where = f"camera_path[{i}]: "
        if not isinstance(entry, dict):
            raise CameraError(f"{path}: {where}expected a JSON object")
        raw = entry.get("camera_to_world")
        shape = (3, 4) if isinstance(raw, list) and len(raw) in (3, 12) else (4, 4)
        c2w = np.eye(4)
        c2w[:shape[0]] = matrix(path, where, entry, "camera_to_world", shape)
        check_rigid_pose(c2w, f"{path}: {where}field 'camera_to_world'")
        fov = number(path, where, entry, "fov")
        try:
            camera = Camera.from_fov(int(w), int(h), fov, np.linalg.inv(c2w @ GL_TO_CV))
        except CameraError as exc:
            raise CameraError(f"{path}: {where}{exc}") from None
        views.append(NamedCamera(f"frame_{i:05d}", camera))
    return views


def camera_path_json(cameras: list[Camera], fps: float = 30.0) -> dict:
    """A ``camera_path.json`` object of ``cameras`` (same size, principal point centred)."""
    c0 = cameras[0]
    path = []
    for c in cameras:
        fov = float(np.degrees(2.0 * np.arctan(0.5 * c.height / c.fy)))
        c2w = np.linalg.inv(c.world_to_camera) @ GL_TO_CV
        path.append({"camera_to_world": c2w.reshape(-1).tolist(), "fov": fov, "aspect": c.width / c.height})
    return {"camera_type": "perspective", "render_width": c0.width, "render_height": c0.height,
            "fps": fps, "seconds": len(cameras) / fps, "camera_path": path}
