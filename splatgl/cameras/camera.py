"""Cameras: a frozen camera in OpenCV axes (+x right, +y down, +z forward) with its model.

Pixel (i, j) (row i from the top, column j) has its centre at image coordinates (j + 0.5, i + 0.5).
Intrinsics (fx, fy, cx, cy) and the pose are the camera's; how camera-space points reach the
image is its :class:`~splatgl.cameras.model.CameraModel` (pinhole by default): perspective,
orthographic, fisheye and equirectangular, each in its own module of :mod:`splatgl.cameras`.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field

import numpy as np

from ..errors import CameraError
from .equirect import Equirectangular
from .fisheye import Fisheye
from .model import CameraModel, CullKind
from .orthographic import Orthographic
from .pinhole import Pinhole
from .poses import MAX_CAMERA_VALUE, MIN_FOCAL, nonfinite_entry


def image_side(value, name: str) -> int:
    """``value`` as an image side in pixels: a whole number >= 1 (an int, a NumPy integer or a
    float without a fraction; not a bool, not a string); else a :class:`CameraError` naming the
    side (``name``: width or height) and the value.  The size limits of the device are checked
    later (:func:`splatgl.renderers.registry.check_image_size`, as for ``--width``)."""
    whole = isinstance(value, numbers.Integral) or (
        isinstance(value, numbers.Real) and math.isfinite(value) and float(value).is_integer())
    if not whole or isinstance(value, (bool, np.bool_)) or value < 1:
        raise CameraError(f"camera {name} must be a positive integer, got {value!r}")
    return int(value)


def _frozen_matrix(m: object) -> np.ndarray:
    arr = np.array(m, dtype=np.float64, copy=True)
    if arr.shape != (4, 4):
        raise CameraError(f"world_to_camera must be a 4x4 matrix, got shape {arr.shape}")
    bad = nonfinite_entry(arr)
    if bad:
        raise CameraError(f"world_to_camera must be finite; it holds {bad}")
    if np.abs(arr).max() > MAX_CAMERA_VALUE:
        i, j = (int(v) for v in np.unravel_index(np.argmax(np.abs(arr)), arr.shape))
        what = "the camera is that far from the origin" if j == 3 else "a scale that large"
        raise CameraError(f"world_to_camera holds {arr[i, j]:.3g} at row {i}, column {j} ({what}); "
                          f"splatgl renders within {MAX_CAMERA_VALUE:.0e} (float32 arithmetic)")
    if not np.allclose(arr[3], [0.0, 0.0, 0.0, 1.0]):
        raise CameraError(f"world_to_camera's last row must be (0, 0, 0, 1), got {arr[3].tolist()}")
    arr.flags.writeable = False
    return arr


@dataclass(frozen=True)
class Camera:
    """A camera; all lengths in pixels except ``world_to_camera``'s translation (world units).

    Attributes:
        width, height: image size in pixels.
        fx, fy: focal lengths in pixels (orthographic: pixels per world unit; fisheye and
            equirectangular: pixels per radian).
        cx, cy: principal point in image coordinates (pixels; (0, 0) is the top-left corner).
        world_to_camera: (4, 4) float64 transform, OpenCV axes: rigid, or rigid times a uniform
            scale when a scene transform is folded in (:func:`splatgl.cameras.view.apply_transform`).
        model: the camera model with its own parameters (:class:`~splatgl.cameras.pinhole.
            Pinhole` by default).
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    world_to_camera: np.ndarray = field(default_factory=lambda: np.eye(4))
    model: CameraModel = field(default_factory=Pinhole)

    def __post_init__(self) -> None:
        for name in ("width", "height"):
            object.__setattr__(self, name, image_side(getattr(self, name), name))
        for name in ("fx", "fy", "cx", "cy"):
            value = float(getattr(self, name))
            if not math.isfinite(value):
                raise CameraError(f"camera {name} must be finite, got {value!r}")
            object.__setattr__(self, name, value)
        if self.fx <= 0 or self.fy <= 0:
            raise CameraError(f"camera focal lengths must be positive, got fx={self.fx}, fy={self.fy}")
        for name in ("fx", "fy", "cx", "cy"):
            value = getattr(self, name)
            focal = name in ("fx", "fy")
            if not (MIN_FOCAL if focal else -MAX_CAMERA_VALUE) <= value <= MAX_CAMERA_VALUE:
                span = (f"from {MIN_FOCAL:g} to " if focal else "within +-")
                raise CameraError(f"camera {name} must be {span}{MAX_CAMERA_VALUE:g} pixels "
                                  f"(float32 arithmetic), got {value:g}")
        object.__setattr__(self, "world_to_camera", _frozen_matrix(self.world_to_camera))
        if not isinstance(self.model, CameraModel):
            raise CameraError(f"camera model must be a CameraModel (splatgl.cameras), got {self.model!r}")

    # ----------------------------------------------------------------------------- factories
    @classmethod
    def from_fov(cls, width: int, height: int, fov_y_degrees: float,
                 world_to_camera: np.ndarray | None = None) -> "Camera":
        """Perspective camera with vertical field of view ``fov_y_degrees``, square pixels."""
        return cls.of_model(Pinhole, width, height, fov_y_degrees, world_to_camera)

    @classmethod
    def from_frustum(cls, width: int, height: int, left: float, right: float, top: float,
                     bottom: float, near: float, far: float | None = None,
                     world_to_camera: np.ndarray | None = None) -> "Camera":
        """Perspective camera from OpenGL-style frustum bounds at the near plane.

        ``left < right`` and ``bottom < top`` are camera-space coordinates on the plane at
        distance ``near`` with GL's y axis pointing up; ``far`` does not change pixels.  The
        image x range [0, W] covers [left, right] and row 0 is at ``top``:
        ``fx = W near / (right - left)``, ``cx = -left W / (right - left)``,
        ``fy = H near / (top - bottom)``, ``cy = top H / (top - bottom)``.
        """
        if not (right > left and top > bottom and near > 0.0):
            raise CameraError("frustum needs left < right, bottom < top and near > 0, got "
                              f"l={left} r={right} b={bottom} t={top} n={near}")
        if far is not None and not far > near:
            raise CameraError(f"frustum far ({far}) must exceed near ({near})")
        fx = width * near / (right - left)
        fy = height * near / (top - bottom)
        cx = -left * width / (right - left)
        cy = top * height / (top - bottom)
        return cls(width, height, fx, fy, cx, cy, _pose(world_to_camera))

    @classmethod
    def orthographic(cls, width: int, height: int, pixels_per_unit: float,
                     world_to_camera: np.ndarray | None = None) -> "Camera":
        """Orthographic camera, ``pixels_per_unit`` pixels per world unit, centred."""
        return cls(width, height, pixels_per_unit, pixels_per_unit, width / 2.0, height / 2.0,
                   _pose(world_to_camera), Orthographic())

    @classmethod
    def fisheye(cls, width: int, height: int, fov_degrees: float,
                world_to_camera: np.ndarray | None = None,
                distortion: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)) -> "Camera":
        """Fisheye camera whose image circle spans ``fov_degrees`` (:meth:`Fisheye.make`)."""
        fx, fy, cx, cy, model = Fisheye.intrinsics(width, height, fov_degrees, k=distortion)
        return cls(width, height, fx, fy, cx, cy, _pose(world_to_camera), model)

    @classmethod
    def equirectangular(cls, width: int, height: int,
                        world_to_camera: np.ndarray | None = None) -> "Camera":
        """Full 360 x 180 degree longitude/latitude panorama (usually ``width = 2 height``)."""
        return cls.of_model(Equirectangular, width, height, None, world_to_camera)

    @classmethod
    def of_model(cls, model: type[CameraModel], width: int, height: int,
                 fov_degrees: float | None = None, world_to_camera: np.ndarray | None = None,
                 like: "Camera | None" = None) -> "Camera":
        """A camera of ``model`` at this size and pose (:meth:`CameraModel.intrinsics`)."""
        width, height = image_side(width, "width"), image_side(height, "height")
        fx, fy, cx, cy, instance = model.intrinsics(width, height, fov_degrees, like)
        return cls(width, height, fx, fy, cx, cy, _pose(world_to_camera), instance)

    def with_pose(self, world_to_camera: np.ndarray) -> "Camera":
        return Camera(self.width, self.height, self.fx, self.fy, self.cx, self.cy,
                      world_to_camera, self.model)

    def with_model(self, model: CameraModel) -> "Camera":
        """The same intrinsics and pose under another model (or other model parameters)."""
        return Camera(self.width, self.height, self.fx, self.fy, self.cx, self.cy,
                      self.world_to_camera, model)

    def resized(self, width: int, height: int) -> "Camera":
        """The same view at another resolution (intrinsics scaled per axis)."""
        width, height = image_side(width, "width"), image_side(height, "height")
        sx, sy = width / self.width, height / self.height
        return Camera(width, height, self.fx * sx, self.fy * sy, self.cx * sx, self.cy * sy,
                      self.world_to_camera, self.model)

    # ----------------------------------------------------------------------------- geometry
    @property
    def projection(self) -> str:
        """The model's name (``"perspective"``, ``"fisheye"``, ...)."""
        return self.model.name

    @property
    def rotation(self) -> np.ndarray:
        """(3, 3) float64 world-to-camera rotation."""
        return self.world_to_camera[:3, :3]

    @property
    def translation(self) -> np.ndarray:
        """(3,) float64 world-to-camera translation."""
        return self.world_to_camera[:3, 3]

    @property
    def center(self) -> np.ndarray:
        """(3,) float64 camera centre in world space (``-R^-1 t``).

        When a scene transform is folded in (:func:`splatgl.cameras.view.apply_transform`), the
        matrix is scene-to-camera and this is the centre in the scene's own frame.
        """
        return -np.linalg.solve(self.rotation, self.translation)

    @property
    def scale(self) -> float:
        """Uniform scale of the 3x3 block (1 for a rigid pose; the transform scale when folded in)."""
        return float(np.cbrt(np.linalg.det(self.rotation)))

    @property
    def is_orthographic(self) -> bool:
        """Whether every pixel's ray has the same direction (the model's ``parallel_rays``)."""
        return self.model.parallel_rays

    @property
    def is_lens(self) -> bool:
        """Projections by angle (the model culls on a sphere): they see behind the camera
        plane, so they cull and sort by distance, not view z."""
        return self.model.cull is CullKind.SPHERE

    @property
    def tan_half_fov(self) -> tuple[float, float]:
        """(tan(fov_x / 2), tan(fov_y / 2)) as the reference computes them: W / (2 fx), H / (2 fy)."""
        return self.width / (2.0 * self.fx), self.height / (2.0 * self.fy)

    def to_json(self) -> dict:
        """The single-camera JSON form (see :func:`splatgl.cameras.camera_files.load_camera`)."""
        return {
            "width": self.width, "height": self.height,
            "fx": self.fx, "fy": self.fy, "cx": self.cx, "cy": self.cy,
            "world_to_camera": self.world_to_camera.tolist(),
            "projection": self.model.name,
            **self.model.to_json(),
        }


def _pose(world_to_camera: np.ndarray | None) -> np.ndarray:
    return np.eye(4) if world_to_camera is None else world_to_camera
