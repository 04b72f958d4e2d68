"""The default camera: a perspective view that frames a scene (:func:`default_camera`, the
CLI's camera when none is given, and the start of the orbit paths)."""

from __future__ import annotations

import math

from ..errors import CameraError
from ..model.scene import Scene
from ..model.transform import ModelTransform
from .camera import Camera
from .pinhole import DEFAULT_FOV
from .poses import orbit

#: Default vertical field of view of :func:`default_camera`, degrees.
DEFAULT_FOV_Y = DEFAULT_FOV
#: Elevation of the default view above the scene's "horizon", degrees.
DEFAULT_ELEVATION = 20.0


def default_camera(scene: Scene, width: int = 1280, height: int = 720,
                   fov_y_degrees: float = DEFAULT_FOV_Y, distance_scale: float = 1.0,
                   model: ModelTransform | None = None, up=(0.0, -1.0, 0.0)) -> Camera:
    """A perspective camera that frames ``scene``.

    Frames the 1st-99th percentile box of the means (so a few stray splats far away do not
    shrink the scene to a dot), from slightly above, with the world direction ``up`` (3,)
    pointing up in the image (default world -y, the COLMAP convention; for a y axis up or down
    it looks along world +z; :func:`splatgl.cameras.up.resolve_up` picks one for a scene), far
    enough that the box's bounding sphere fits the narrower fov, times ``distance_scale``
    (below 1 moves closer).  With a ``model`` transform the scene is framed where the transform
    places it.  Raises :class:`~splatgl.errors.CameraError` for a size that is not a positive
    integer, a field of view outside (0, 180) degrees or a distance scale that is not positive.
    """
    for name, value in (("width", width), ("height", height)):
        if isinstance(value, bool) or int(value) != value or value < 1:
            raise CameraError(f"camera {name} must be a positive integer, got {value!r}")
    if not 0.0 < fov_y_degrees < 180.0:
        raise CameraError(f"field of view must be in (0, 180) degrees, got {fov_y_degrees}")
    if not (math.isfinite(distance_scale) and distance_scale > 0.0):
        raise CameraError(f"distance scale must be a finite number > 0, got {distance_scale}")
    lo, hi = scene.robust_bounds
    centre = 0.5 * (lo + hi)
    radius = max(scene.robust_radius, 1e-6)
    if model is not None:
        centre = model.apply_points(centre[None])[0]
        radius *= model.scale
    fov_y = math.radians(fov_y_degrees)
    fov_x = 2.0 * math.atan(math.tan(fov_y / 2.0) * width / height)
    half = min(fov_x, fov_y) / 2.0
    distance = 1.05 * radius / math.sin(half) * distance_scale
    pose = orbit(centre, distance, 180.0, DEFAULT_ELEVATION, up)
    return Camera.from_fov(width, height, fov_y_degrees, pose)
