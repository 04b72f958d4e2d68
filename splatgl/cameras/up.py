"""Which world direction is "up" for a default view: an ``--up`` axis, or the training cameras'.

Trained scenes carry no up axis of their own.  COLMAP (and so most 3DGS training) usually ends
with world -y up, which is splatgl's fallback; scenes trained elsewhere may be z-up or flipped
(the donut in the shared scenes is seen from below with -y).  When a scene comes with its
training cameras (a 3DGS ``cameras.json``), their average image-up direction is the best guess:
for a world-to-camera rotation R in OpenCV axes (+y image-down) a camera's up is ``-R[1]``.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .camera import Camera

#: ``--up`` choices and their world vectors.
UP_AXES = {"+y": (0.0, 1.0, 0.0), "-y": (0.0, -1.0, 0.0), "+z": (0.0, 0.0, 1.0), "-z": (0.0, 0.0, -1.0)}
UP_CHOICES = tuple(UP_AXES)
#: The fallback: world -y, the COLMAP convention.
DEFAULT_UP = "-y"
#: The name 3DGS training gives its camera list, and how many folders above a scene file it may
#: sit (``OUT/point_cloud/iteration_30000/point_cloud.ply`` beside ``OUT/cameras.json``).
CAMERAS_NAME = "cameras.json"
CAMERAS_SEARCH_DEPTH = 3


def average_up(cameras: list[Camera]) -> np.ndarray | None:
    """(3,) float64 unit mean of the cameras' up directions (``-R[1]`` each), or None when they
    cancel out (less than 10 % of a unit agrees) or there are none."""
    if not cameras:
        return None
    ups = np.array([-np.asarray(c.rotation)[1] / np.linalg.norm(c.rotation[1]) for c in cameras])
    mean = ups.mean(axis=0)
    norm = float(np.linalg.norm(mean))
    return mean / norm if norm > 0.1 else None


def cameras_beside(scene_path: Path | None) -> Path | None:
    """A ``cameras.json`` in the scene's folder or up to :data:`CAMERAS_SEARCH_DEPTH` above it."""
    if scene_path is None:
        return None
    folder = Path(os.path.abspath(scene_path)).parent  # beside the name given, links not followed
    for _ in range(CAMERAS_SEARCH_DEPTH + 1):
        candidate = folder / CAMERAS_NAME
        if candidate.is_file():
            return candidate
        if folder.parent == folder:
            break
        folder = folder.parent
    return None


def resolve_up(choice: str | None, scene_path: Path | None = None,
               camera_file: Path | None = None) -> tuple[np.ndarray, str]:
    """The up vector of a default view and where it came from (for messages).

    ``choice`` (an ``--up`` value) wins; else the average up of ``camera_file`` or of a
    ``cameras.json`` found beside the scene; else :data:`DEFAULT_UP`.  A camera file found
    beside the scene that cannot be read is ignored (it was not asked for); one given is read
    with its errors reported.
    """
    if choice is not None:
        return np.array(UP_AXES[choice]), f"--up {choice}"
    from .camera_files import load_cameras
    from ..errors import CameraError

    if camera_file is not None:
        up = average_up(load_cameras(camera_file))
        if up is not None:
            return up, f"the average up of {camera_file}"
    found = cameras_beside(scene_path)
    if found is not None:
        try:
            up = average_up(load_cameras(found))
        except CameraError:
            up = None
        if up is not None:
            return up, f"the average up of {found}"
    return np.array(UP_AXES[DEFAULT_UP]), f"{DEFAULT_UP} (COLMAP convention)"
