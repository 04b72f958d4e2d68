"""3DGS ``cameras.json`` (written by its ``train.py``): a list of ``{"id", "img_name", "width",
"height", "position", "rotation", "fx", "fy"}``.

Axes: ``rotation`` is camera-to-world (3x3, rows as stored) in OpenCV camera axes and
``position`` the camera centre, so ``world_to_camera = [R^T | -R^T position]``; the principal
point is the image centre (3DGS renders with a centred principal point).
"""

from __future__ import annotations

from pathlib import Path

from ..cameras.camera_files import camera_from_3dgs
from ..errors import CameraError
from .named_camera import NamedCamera


def load_gs_cameras(path: Path, obj: list) -> list[NamedCamera]:
    if not obj:
        raise CameraError(f"{path}: the camera list is empty")
    views = []
    for i, entry in enumerate(obj):
        camera = camera_from_3dgs(entry, path, i)
        name = entry.get("img_name", f"camera_{i:05d}") if isinstance(entry, dict) else f"camera_{i:05d}"
        views.append(NamedCamera(str(name), camera))
    return views


def gs_cameras_json(views: list[NamedCamera]) -> list[dict]:
    """The ``cameras.json`` list of ``views`` (their principal points must be centred)."""
    out = []
    for i, v in enumerate(views):
        c = v.camera
        out.append({"id": i, "img_name": v.name, "width": c.width, "height": c.height,
                    "position": c.center.tolist(), "rotation": c.rotation.T.tolist(),
                    "fx": c.fx, "fy": c.fy})
    return out
