"""The camera models by name: the CLI's ``--projection`` choices, camera files' "projection"
field, the COLMAP and ``transforms.json`` camera model names each model reads, and
re-projecting a camera to another model.

One line per model in :data:`MODELS`; everything else about a model lives in its own module.
A COLMAP or ``transforms.json`` name belongs to the last model in :data:`MODELS` that lists it
(:attr:`~splatgl.cameras.model.CameraModel.colmap_names`, ``transforms_names``), so a model
registered later takes a name over from an earlier one.
"""

from __future__ import annotations

from ..errors import CameraError
from .camera import Camera, image_side
from .equirect import Equirectangular
from .fisheye import Fisheye
from .model import CameraModel
from .opencv import OpenCV
from .orthographic import Orthographic
from .pinhole import Pinhole

#: Every camera model, by its name.  The first is the default.
MODELS: dict[str, type[CameraModel]] = {m.name: m for m in (
    Pinhole,
    Orthographic,
    Fisheye,
    Equirectangular,
    OpenCV,
)}


#: Image size of a camera made without one (:func:`default_size`).
DEFAULT_WIDTH, DEFAULT_HEIGHT = 1280, 720


def _claims(attr: str) -> dict[str, type[CameraModel]]:
    """Each name listed in the models' ``attr`` -> the last model listing it, in order of first
    listing."""
    table: dict[str, type[CameraModel]] = {}
    for model in MODELS.values():
        for name in getattr(model, attr):
            table[name] = model
    return table


#: COLMAP camera model name -> the model that reads it.
COLMAP = _claims("colmap_names")
#: ``transforms.json`` ``camera_model`` value -> the model that reads it.
TRANSFORMS = _claims("transforms_names")


def names() -> list[str]:
    """The model names, default first (``--projection`` choices)."""
    return list(MODELS)


def model_class(name: str, what: str = "projection") -> type[CameraModel]:
    """The model class called ``name``; a one-line CameraError naming the choices otherwise."""
    try:
        return MODELS[name]
    except (KeyError, TypeError):
        choices = ", ".join(f"'{n}'" for n in MODELS)
        raise CameraError(f"{what} must be one of {choices}, got {name!r}") from None


def default_size(name: str | None, width: int | None = None,
                 height: int | None = None) -> tuple[int, int]:
    """The image size of a camera of the model called ``name`` (None: the default perspective
    camera) made without one, or with only one side given: :data:`DEFAULT_WIDTH` x
    :data:`DEFAULT_HEIGHT` and the sides given, or for a model with its own aspect (an
    equirectangular panorama: 2:1) that aspect, at the default height when neither is given."""
    aspect = model_class(name or names()[0]).aspect
    if aspect is not None:
        height = height or (max(1, round(width / aspect)) if width else DEFAULT_HEIGHT)
        width = width or round(aspect * height)
    else:
        width, height = width or DEFAULT_WIDTH, height or DEFAULT_HEIGHT
    return width, height


def check_fov(name: str | None, fov_degrees: float | None) -> None:
    """Raise :class:`CameraError` for a field of view outside the model's range, or given to a
    model without one (``name`` None: the default perspective camera)."""
    if fov_degrees is None:
        return
    cls = model_class(name or names()[0])
    check_fov_applies(cls.name, fov_degrees)
    lo, hi, closed = cls.fov_range()
    if not (lo < fov_degrees <= hi if closed else lo < fov_degrees < hi):
        what = f"--fov of a {cls.name}" if cls.name != names()[0] else "--fov"
        raise CameraError(f"{what} must be in ({lo:g}, {hi:g}{']' if closed else ')'} degrees, "
                          f"got {fov_degrees:g}")


def check_fov_applies(name: str, fov_degrees: float | None) -> None:
    """Raise :class:`CameraError` for a field of view given to a model without one (an
    equirectangular panorama spans 360 x 180 degrees; an orthographic scale is pixels per
    world unit)."""
    cls = model_class(name)
    if fov_degrees is not None and cls.no_fov:
        raise CameraError(f"--fov {fov_degrees:g} does not apply: {cls.no_fov}")


def retarget(camera: Camera, name: str, fov_degrees: float | None = None) -> Camera:
    """``camera``'s pose and image size under the model called ``name`` (the CLI's
    ``--projection``, ``--fov``): each model's :meth:`~CameraModel.intrinsics` decides what it
    keeps.  A field of view for a model without one is refused (:func:`check_fov_applies`)."""
    check_fov_applies(name, fov_degrees)
    cls = model_class(name)
    if isinstance(camera.model, cls) and fov_degrees is None:
        return camera
    return Camera.of_model(cls, camera.width, camera.height, fov_degrees, camera.world_to_camera,
                           like=camera)


def replaces_intrinsics(camera: Camera, name: str | None, fov_degrees: float | None) -> bool:
    """Whether :func:`retarget` builds new intrinsics for ``camera`` (keeping only its pose):
    another model that makes its own, or a field of view."""
    cls = type(camera.model) if name is None else model_class(name)
    if cls.keeps_intrinsics:
        return False
    return not isinstance(camera.model, cls) or fov_degrees is not None


def adapt_camera(camera: Camera, width: int | None = None, height: int | None = None,
                 name: str | None = None, fov_degrees: float | None = None,
                 source: str = "the camera") -> Camera:
    """A camera read from a file, at the asked image size and model (``--camera`` with
    ``--width``, ``--height``, ``--projection``, ``--fov``; :func:`splatgl.load_camera`).

    - Its own intrinsics (no other model, no field of view): ``width`` and/or ``height``
      scale them; one of the two keeps the file's aspect, both must keep it.
    - New intrinsics (:func:`replaces_intrinsics`: e.g. a fisheye or panorama from a pinhole
      file): only the pose is the file's, and any ``width`` x ``height`` is allowed.  A
      missing side follows the file's aspect, or the model's own (a panorama's 2:1, whose
      height defaults to the file's).

    ``source`` (the file's name) appears in messages.

    Raises:
        CameraError: a side that is not a positive integer (:func:`~splatgl.cameras.camera.
            image_side`); both sides given in another aspect than the file's own intrinsics; a field
            of view the model has none of (:func:`check_fov_applies`).
    """
    w = None if width is None else image_side(width, "width")
    h = None if height is None else image_side(height, "height")
    if not replaces_intrinsics(camera, name, fov_degrees):
        if w and h and w != round(camera.width * h / camera.height) \
                and h != round(camera.height * w / camera.width):
            raise CameraError(
                f"--width {w} --height {h} would stretch {source}'s {camera.width}x{camera.height} "
                f"view (aspect {camera.width / camera.height:.4g}, asked {w / h:.4g}); give only "
                "one of them to scale keeping the aspect")
        if w or h:
            camera = camera.resized(w or max(1, round(camera.width * h / camera.height)),
                                    h or max(1, round(camera.height * w / camera.width)))
        if name is None and fov_degrees is None:
            return camera
        return retarget(camera, camera.model.name if name is None else name, fov_degrees)
    cls = type(camera.model) if name is None else model_class(name)
    if cls.aspect is not None:
        h = h or (max(1, round(w / cls.aspect)) if w else camera.height)
        w = w or round(cls.aspect * h)
    else:
        w = w or (max(1, round(camera.width * h / camera.height)) if h else camera.width)
        h = h or max(1, round(camera.height * w / camera.width))
    return retarget(camera.resized(w, h), cls.name, fov_degrees)  # keeps only the pose
