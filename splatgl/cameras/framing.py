"""The default camera: a view of any camera model that frames a scene (:func:`default_camera`,
the CLI's camera when none is given, and the start of the orbit paths)."""

from __future__ import annotations

import math

import numpy as np

from ..errors import CameraError
from ..scene.splats import Scene, require_scene
from ..scene.transform import SceneTransform
from . import registry
from .camera import MAX_CAMERA_VALUE, MIN_FOCAL, Camera, image_side
from .orthographic import Orthographic
from .pinhole import DEFAULT_FOV, Pinhole
from .poses import orbit
from .up import UP_AXES, resolve_up

#: Default vertical field of view of :func:`default_camera`'s perspective camera, degrees.
DEFAULT_FOV_Y = DEFAULT_FOV
#: Elevation of the default view above the scene's "horizon", degrees.
DEFAULT_ELEVATION = 20.0
#: The orthographic default camera's image spans this many robust radii of the scene across
#: its narrower side.
ORTHOGRAPHIC_SPAN = 2.1


def default_camera(scene: Scene, width: int | None = None, height: int | None = None,
                   fov_degrees: float | None = None, distance_scale: float = 1.0,
                   model: SceneTransform | None = None, up=None, *,
                   projection: str | None = None) -> Camera:
    """A camera that frames ``scene``: what ``splatgl render`` draws without ``--camera``.

    Frames the 1st-99th percentile box of the means (so a few stray splats far away do not
    shrink the scene to a dot), from slightly above, far enough that the box's bounding sphere
    fits the narrower field of view of a perspective camera, times ``distance_scale`` (below 1
    moves closer).  With a ``model`` transform the scene is framed where the transform places
    it.

    - ``projection``: a camera model's name (:func:`splatgl.cameras.registry.names`; default
      perspective).  Fisheye and equirectangular cameras take the perspective camera's pose;
      an orthographic one is zoomed so that its narrower side spans
      :data:`ORTHOGRAPHIC_SPAN` robust radii (times ``distance_scale``).
    - ``width``, ``height``: the image size; a missing side is the model's default
      (:func:`splatgl.cameras.registry.default_size`: 1280 x 720, a panorama 2:1).
    - ``fov_degrees``: the model's field of view (perspective: vertical, default 50; fisheye:
      the image circle's, default 180); refused for a model without one.
    - ``up``: the world direction pointing up in the image: a 3-vector, an axis name ("+y",
      "-y", "+z", "-z"), or None for the scene's own (:func:`splatgl.cameras.up.resolve_up`:
      the average up of the training cameras in a ``cameras.json`` beside the scene's file,
      else world -y, the COLMAP convention).  For a y axis up or down it looks along world +z.

    Raises :class:`~splatgl.errors.CameraError` for an unknown projection, a size that is not a
    positive integer, a field of view outside the model's range and a distance scale that is
    not positive, with the messages ``splatgl render`` gives.
    """
    # what the framing reads: a streamed scene's framing proxy stands in for a Scene
    require_scene(scene, "default_camera", ("robust_bounds", "robust_radius", "source"))
    cls = registry.model_class(projection or registry.names()[0])
    width = None if width is None else image_side(width, "width")
    height = None if height is None else image_side(height, "height")
    width, height = registry.default_size(cls.name, width, height)
    registry.check_fov(cls.name, fov_degrees)
    if not (math.isfinite(distance_scale) and distance_scale > 0.0):
        raise CameraError(f"distance scale must be a finite number > 0, got {distance_scale}")
    pinhole = cls is Pinhole
    fov_y = fov_degrees if pinhole and fov_degrees is not None else DEFAULT_FOV_Y
    cam = _framing_camera(scene, width, height, fov_y, distance_scale, model, _up_vector(scene, up))
    if cls is Orthographic:  # parallel rays: the zoom frames the scene
        scale = model.scale if model is not None else 1.0
        radius = max(scene.robust_radius * scale, 1e-9) * distance_scale
        zoom = min(width, height) / (ORTHOGRAPHIC_SPAN * radius)
        if not MIN_FOCAL <= zoom <= MAX_CAMERA_VALUE:
            raise CameraError(f"distance scale {distance_scale:g} zooms the orthographic camera to "
                              f"{zoom:.3g} pixels per world unit (scene radius {radius:.3g}); "
                              f"splatgl renders from {MIN_FOCAL:g} to {MAX_CAMERA_VALUE:g} "
                              "(float32 arithmetic)")
        return Camera.orthographic(width, height, zoom, cam.world_to_camera)
    return cam if pinhole else registry.retarget(cam, cls.name, fov_degrees)


def _up_vector(scene: Scene, up) -> np.ndarray:
    """``up`` of :func:`default_camera` as a world vector."""
    if up is None or isinstance(up, str):
        if isinstance(up, str) and up not in UP_AXES:
            raise CameraError(f"up must be one of {', '.join(UP_AXES)} or a 3-vector, got {up!r}")
        return resolve_up(up, scene.source.path if scene.source is not None else None)[0]
    return np.asarray(up, np.float64)


#: The closest the default camera stands to the scene's centre, relative to the centre's own
#: distance from the origin (at least 1): closer, float64 cannot tell the eye from the target
#: (a 1e-300 scale) and float32 cannot render it.
MIN_FRAMING_DISTANCE = 1e-9


def _framing_camera(scene: Scene, width: int, height: int, fov_y_degrees: float,
                    distance_scale: float, model: SceneTransform | None, up) -> Camera:
    """The perspective default camera (see :func:`default_camera`)."""
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
    far, near = float(np.abs(centre).max()), MIN_FRAMING_DISTANCE * max(float(np.abs(centre).max()), 1.0)
    sizes = f"(scene radius {radius:.3g}, distance scale {distance_scale:g})"
    if not far <= MAX_CAMERA_VALUE / 2:   # inf, NaN too
        raise CameraError(f"cannot frame the scene: its centre lies {far:.3g} from the origin "
                          f"{sizes}; splatgl renders within {MAX_CAMERA_VALUE / 2:g} (float32 arithmetic)")
    if not near <= distance <= MAX_CAMERA_VALUE / 2:
        raise CameraError(f"cannot frame the scene: the camera would stand {distance:.3g} from "
                          f"it {sizes}; splatgl places it from {near:.3g} to "
                          f"{MAX_CAMERA_VALUE / 2:g} away (float arithmetic)")
    pose = orbit(centre, distance, 180.0, DEFAULT_ELEVATION, up)
    return Camera.from_fov(width, height, fov_y_degrees, pose)
