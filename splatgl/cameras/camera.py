"""Cameras: a frozen camera in OpenCV axes (+x right, +y down, +z forward).

Pixel (i, j) (row i from the top, column j) has its centre at image coordinates (j + 0.5, i + 0.5).
Perspective: ``u = fx x / z + cx``, ``v = fy y / z + cy`` with (x, y, z) in camera space.
Orthographic: ``u = fx x + cx``, ``v = fy y + cy`` (fx, fy in pixels per world unit).
Fisheye (OpenCV's fisheye model; equidistant when k1..k4 are 0): ``theta = atan2(rho, z)`` with
``rho = sqrt(x^2 + y^2)``, ``theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4
theta^8)``, ``u = fx theta_d x / rho + cx``, ``v = fy theta_d y / rho + cy`` (fx, fy in pixels
per radian).
Equirectangular: ``lon = atan2(x, z)``, ``lat = atan2(y, sqrt(x^2 + z^2))`` (positive below the
horizon), ``u = fx lon + cx``, ``v = fy lat + cy``; a full panorama has ``fx = W / 2 pi``,
``fy = H / pi`` and the principal point at the image centre.  See :mod:`splatgl.cameras.lens`.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field

import numpy as np

from ..constants import RIGID_POSE_TOLERANCE
from ..errors import CameraError


class Projection(enum.Enum):
    PERSPECTIVE = "perspective"
    ORTHOGRAPHIC = "orthographic"
    FISHEYE = "fisheye"
    EQUIRECTANGULAR = "equirectangular"


def _frozen_matrix(m: object) -> np.ndarray:
    arr = np.array(m, dtype=np.float64, copy=True)
    if arr.shape != (4, 4):
        raise CameraError(f"world_to_camera must be a 4x4 matrix, got shape {arr.shape}")
    bad = _first_bad(arr)
    if bad:
        raise CameraError(f"world_to_camera must be finite; it holds {bad}")
    if not np.allclose(arr[3], [0.0, 0.0, 0.0, 1.0]):
        raise CameraError(f"world_to_camera's last row must be (0, 0, 0, 1), got {arr[3].tolist()}")
    arr.flags.writeable = False
    return arr


def _first_bad(arr: np.ndarray) -> str | None:
    """'NaN at row 1, column 2' for the first non-finite entry of a 2D array, else None."""
    bad = np.argwhere(~np.isfinite(arr))
    if not len(bad):
        return None
    i, j = (int(v) for v in bad[0])
    return f"{'NaN' if np.isnan(arr[i, j]) else 'Inf'} at row {i}, column {j}"


def rigid_pose_problem(matrix: object, tolerance: float = RIGID_POSE_TOLERANCE) -> str | None:
    """What keeps a camera pose from being a rigid transform, or None when it is one.

    A rigid pose is a rotation (orthonormal rows, determinant +1) plus a translation: no scale,
    shear or mirror.  Camera files must hold one; only :func:`splatgl.model.transform.apply_model`
    folds a uniform scale into a camera afterwards.

    Args:
        matrix: (4, 4) world-to-camera (last row must be 0, 0, 0, 1) or (3, 3) rotation, numbers.
        tolerance: largest accepted entry of ``|R R^T - I|`` and ``|det R - 1|``
            (default :data:`splatgl.constants.RIGID_POSE_TOLERANCE`).

    Returns:
        None, or a phrase to follow a field name, e.g. ``"is mirrored (determinant -1)"``,
        ``"holds NaN at row 1, column 2"``.  Every loader uses this one check, so a bad pose
        reads the same whichever file it came from.
    """
    arr = np.asarray(matrix, dtype=np.float64)
    if arr.shape not in ((4, 4), (3, 3)):
        return f"must be a 4x4 or 3x3 matrix, got shape {arr.shape}"
    bad = _first_bad(arr)
    if bad:
        return f"holds {bad}"
    if arr.shape == (4, 4) and not np.allclose(arr[3], [0.0, 0.0, 0.0, 1.0], rtol=0.0, atol=tolerance):
        return f"must have (0, 0, 0, 1) as its last row, got {[float(v) for v in arr[3]]}"
    r = arr[:3, :3]
    det = float(np.linalg.det(r))
    norms = np.linalg.norm(r, axis=1)
    if abs(det) <= tolerance * float(np.prod(norms)):  # Hadamard: |det| <= product of row norms
        return f"is singular (determinant {det:.3g}): not a rotation"
    unit = r / norms[:, None]
    off_diagonal = float(np.abs(unit @ unit.T - np.eye(3)).max())
    if off_diagonal > tolerance:
        return (f"is sheared (its rotation rows are not orthogonal: largest |cos angle| "
                f"{off_diagonal:.3g}, tolerance {tolerance:g}): not a rigid transform")
    if np.abs(norms - 1.0).max() > tolerance:
        lengths = ", ".join(f"{v:.6g}" for v in norms)
        return f"is scaled (its rotation rows have lengths {lengths}, not 1): not a rigid transform"
    if det < 0:
        return f"is mirrored (determinant {det:.6g}, not +1): not a rotation"
    return None


def check_rigid_pose(matrix: object, what: str, tolerance: float = RIGID_POSE_TOLERANCE) -> np.ndarray:
    """``matrix`` as a float64 array if :func:`rigid_pose_problem` finds nothing wrong.

    Raises:
        CameraError: ``"{what} {problem}"``, e.g. ``"cams.json: camera 3: field 'rotation' is
            mirrored (determinant -1, not +1): not a rotation"``.
    """
    problem = rigid_pose_problem(matrix, tolerance)
    if problem:
        raise CameraError(f"{what} {problem}")
    return np.asarray(matrix, dtype=np.float64)


@dataclass(frozen=True)
class Camera:
    """A camera; all lengths in pixels except ``world_to_camera``'s translation (world units).

    Attributes:
        width, height: image size in pixels.
        fx, fy: focal lengths in pixels (orthographic: pixels per world unit).
        cx, cy: principal point in image coordinates (pixels; (0, 0) is the top-left corner).
        world_to_camera: (4, 4) float64 transform, OpenCV axes: rigid, or rigid times a uniform
            scale when a model transform is folded in (:func:`splatgl.model.transform.apply_model`).
        projection: perspective, orthographic, fisheye or equirectangular.
        distortion: fisheye coefficients (k1, k2, k3, k4) of ``theta_d``; zeros otherwise.
        ods_eye: equirectangular only: signed eye offset (world units, -IPD/2 for the left eye,
            +IPD/2 for the right) of omni-directional stereo; 0 for a mono panorama.  Each
            splat is seen from the point of the eye circle whose tangent ray reaches it
            (:func:`splatgl.cameras.lens.eye_space`).
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    world_to_camera: np.ndarray = field(default_factory=lambda: np.eye(4))
    projection: Projection = Projection.PERSPECTIVE
    distortion: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    ods_eye: float = 0.0

    def __post_init__(self) -> None:
        for name in ("width", "height"):
            value = getattr(self, name)
            if int(value) != value or int(value) < 1:
                raise CameraError(f"camera {name} must be a positive integer, got {value!r}")
            object.__setattr__(self, name, int(value))
        for name in ("fx", "fy", "cx", "cy"):
            value = float(getattr(self, name))
            if not math.isfinite(value):
                raise CameraError(f"camera {name} must be finite, got {value!r}")
            object.__setattr__(self, name, value)
        if self.fx <= 0 or self.fy <= 0:
            raise CameraError(f"camera focal lengths must be positive, got fx={self.fx}, fy={self.fy}")
        object.__setattr__(self, "world_to_camera", _frozen_matrix(self.world_to_camera))
        object.__setattr__(self, "projection", Projection(self.projection))
        k = tuple(float(v) for v in self.distortion)
        if len(k) != 4 or not all(math.isfinite(v) for v in k):
            raise CameraError(f"camera distortion must be 4 finite numbers (k1..k4), got {self.distortion!r}")
        if any(k) and self.projection is not Projection.FISHEYE:
            raise CameraError(f"distortion coefficients apply to fisheye cameras only, not {self.projection.value}")
        object.__setattr__(self, "distortion", k)
        ods = float(self.ods_eye)
        if not math.isfinite(ods) or (ods and self.projection is not Projection.EQUIRECTANGULAR):
            raise CameraError(f"an omni-directional stereo eye offset needs a finite value and an "
                              f"equirectangular camera, got {self.ods_eye!r} ({self.projection.value})")
        object.__setattr__(self, "ods_eye", ods)

    # ----------------------------------------------------------------------------- factories
    @classmethod
    def from_fov(cls, width: int, height: int, fov_y_degrees: float,
                 world_to_camera: np.ndarray | None = None) -> "Camera":
        """Perspective camera with vertical field of view ``fov_y_degrees``, square pixels."""
        if not 0.0 < fov_y_degrees < 180.0:
            raise CameraError(f"field of view must be in (0, 180) degrees, got {fov_y_degrees}")
        f = 0.5 * height / math.tan(math.radians(fov_y_degrees) / 2.0)
        return cls(width, height, f, f, width / 2.0, height / 2.0,
                   np.eye(4) if world_to_camera is None else world_to_camera)

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
        return cls(width, height, fx, fy, cx, cy,
                   np.eye(4) if world_to_camera is None else world_to_camera)

    @classmethod
    def orthographic(cls, width: int, height: int, pixels_per_unit: float,
                     world_to_camera: np.ndarray | None = None) -> "Camera":
        """Orthographic camera, ``pixels_per_unit`` pixels per world unit, centred."""
        return cls(width, height, pixels_per_unit, pixels_per_unit, width / 2.0, height / 2.0,
                   np.eye(4) if world_to_camera is None else world_to_camera,
                   Projection.ORTHOGRAPHIC)

    @classmethod
    def fisheye(cls, width: int, height: int, fov_degrees: float,
                world_to_camera: np.ndarray | None = None,
                distortion: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)) -> "Camera":
        """Fisheye camera whose image circle of diameter ``min(W, H)`` spans ``fov_degrees``
        (any angle up to 360), centred; with distortion, ``theta_d`` of the half angle is what
        reaches the circle's edge."""
        if not 0.0 < fov_degrees <= 360.0:
            raise CameraError(f"fisheye field of view must be in (0, 360] degrees, got {fov_degrees}")
        half = math.radians(fov_degrees) / 2.0
        k1, k2, k3, k4 = (float(v) for v in distortion)
        theta_d = half * (1 + k1 * half ** 2 + k2 * half ** 4 + k3 * half ** 6 + k4 * half ** 8)
        if not theta_d > 0.0:
            raise CameraError(f"fisheye distortion {tuple(distortion)} maps the half angle to {theta_d}")
        f = 0.5 * min(width, height) / theta_d
        return cls(width, height, f, f, width / 2.0, height / 2.0,
                   np.eye(4) if world_to_camera is None else world_to_camera,
                   Projection.FISHEYE, (k1, k2, k3, k4))

    @classmethod
    def equirectangular(cls, width: int, height: int,
                        world_to_camera: np.ndarray | None = None) -> "Camera":
        """Full 360 x 180 degree longitude/latitude panorama (usually ``width = 2 height``)."""
        return cls(width, height, width / (2.0 * math.pi), height / math.pi, width / 2.0,
                   height / 2.0, np.eye(4) if world_to_camera is None else world_to_camera,
                   Projection.EQUIRECTANGULAR)

    def with_pose(self, world_to_camera: np.ndarray) -> "Camera":
        return Camera(self.width, self.height, self.fx, self.fy, self.cx, self.cy,
                      world_to_camera, self.projection, self.distortion, self.ods_eye)

    def resized(self, width: int, height: int) -> "Camera":
        """The same view at another resolution (intrinsics scaled per axis)."""
        sx, sy = width / self.width, height / self.height
        return Camera(width, height, self.fx * sx, self.fy * sy, self.cx * sx, self.cy * sy,
                      self.world_to_camera, self.projection, self.distortion, self.ods_eye)

    # ----------------------------------------------------------------------------- geometry
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

        When a model transform is folded in (:func:`splatgl.model.transform.apply_model`), the matrix
        is scene-to-camera and this is the centre in the scene's own frame.
        """
        return -np.linalg.solve(self.rotation, self.translation)

    @property
    def scale(self) -> float:
        """Uniform scale of the 3x3 block (1 for a rigid pose; the model scale when folded in)."""
        return float(np.cbrt(np.linalg.det(self.rotation)))

    @property
    def is_orthographic(self) -> bool:
        return self.projection is Projection.ORTHOGRAPHIC

    @property
    def is_lens(self) -> bool:
        """Fisheye or equirectangular: projections by angle (:mod:`splatgl.cameras.lens`), which see
        behind the camera plane, so they cull and sort by distance, not view z."""
        return self.projection in (Projection.FISHEYE, Projection.EQUIRECTANGULAR)

    @property
    def tan_half_fov(self) -> tuple[float, float]:
        """(tan(fov_x / 2), tan(fov_y / 2)) as the reference computes them: W / (2 fx), H / (2 fy)."""
        return self.width / (2.0 * self.fx), self.height / (2.0 * self.fy)

    def to_json(self) -> dict:
        """The single-camera JSON form (see :func:`splatgl.cameras.files.load_camera`)."""
        return {
            "width": self.width, "height": self.height,
            "fx": self.fx, "fy": self.fy, "cx": self.cx, "cy": self.cy,
            "world_to_camera": self.world_to_camera.tolist(),
            "projection": self.projection.value,
            **({"distortion": list(self.distortion)} if any(self.distortion) else {}),
            **({"ods_eye": self.ods_eye} if self.ods_eye else {}),
        }


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray = (0.0, -1.0, 0.0)) -> np.ndarray:
    """(4, 4) world-to-camera matrix (OpenCV axes) for a camera at ``eye`` looking at ``target``.

    ``up`` is the world direction that should appear up in the image; the default (0, -1, 0)
    suits scenes trained from COLMAP, whose world y axis usually points down.
    """
    eye = np.asarray(eye, np.float64)
    forward = np.asarray(target, np.float64) - eye
    norm = np.linalg.norm(forward)
    if not norm > 0.0:
        raise CameraError("look_at: eye and target coincide")
    z = forward / norm
    up = np.asarray(up, np.float64)
    x = np.cross(z, up)  # camera y is image-down, about -up; x = y cross z = z cross up
    if np.linalg.norm(x) < 1e-9:
        x = np.cross(z, [1.0, 0.0, 0.0] if abs(z[0]) < 0.9 else [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    m = np.eye(4)
    m[:3, :3] = np.stack([x, y, z])
    m[:3, 3] = -m[:3, :3] @ eye
    return m


def orbit(target: np.ndarray, distance: float, azimuth_degrees: float, elevation_degrees: float,
          up: np.ndarray = (0.0, -1.0, 0.0)) -> np.ndarray:
    """World-to-camera matrix of a camera orbiting ``target`` at ``distance``.

    Azimuth turns about ``up``; elevation lifts the camera towards ``up`` (degrees).
    """
    up = np.asarray(up, np.float64)
    up = up / np.linalg.norm(up)
    # Any unit vector orthogonal to up serves as azimuth 0.
    ref = np.array([0.0, 0.0, 1.0]) if abs(up[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    a = ref - up * (ref @ up)
    a /= np.linalg.norm(a)
    b = np.cross(up, a)
    az, el = math.radians(azimuth_degrees), math.radians(elevation_degrees)
    direction = math.cos(el) * (math.cos(az) * a + math.sin(az) * b) + math.sin(el) * up
    eye = np.asarray(target, np.float64) + distance * direction
    return look_at(eye, target, up)
