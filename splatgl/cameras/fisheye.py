"""The fisheye camera: OpenCV's ``cv::fisheye`` model (equidistant when k1..k4 are 0).

COLMAP's ``OPENCV_FISHEYE`` (and, with fewer coefficients, ``RADIAL_FISHEYE`` and
``SIMPLE_RADIAL_FISHEYE``) and gsplat's ``fisheye`` camera are this model.  Shader piece:
``shaders/cameras/fisheye.glsl`` (same names).  Camera space, OpenCV axes; fx, fy in pixels per
radian:

``rho = sqrt(x^2 + y^2)``, ``theta = atan2(rho, z)``, ``g(theta) = theta (1 + k1 theta^2 + k2
theta^4 + k3 theta^6 + k4 theta^8)``, ``s = g / rho``, ``u = fx s x + cx``, ``v = fy s y + cy``.
With ``R^2 = rho^2 + z^2`` and ``c2 = (g' z / R^2 - s) / rho^2``:
``J = [[fx (s + x^2 c2), fx x y c2, -fx x g' / R^2], [fy x y c2, fy (s + y^2 c2), -fy y g' / R^2]]``.
Near the axis (``rho < FISHEYE_SERIES_RHO z``) ``s`` and ``c2`` cancel; their series
``s = (1 + (k1 - 1/3) t) / z`` and ``c2 = (2 k1 - 2/3) / z^3`` (``t = rho^2 / z^2``) are used.

A fisheye sees behind the camera plane (more than 180 degrees), so it culls and sorts by the
distance ``R = |p|``: a splat is kept when ``R > near`` and its centre lies within
:meth:`Fisheye.angle_limit` of the axis.  Along one pixel's ray distance and view z order points
the same way; between splats in different directions they can differ, as z and the true
per-pixel depth already do for a pinhole camera (the sort is per splat, not per pixel).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from ..constants import FISHEYE_SERIES_RHO, FISHEYE_THETA_CAP, FISHEYE_THETA_MARGIN
from ..errors import CameraError
from .model import CullKind, LensDistortion, colmap_intrinsics

if TYPE_CHECKING:
    from .camera import Camera

#: Field of view across the image circle of a fisheye made without one (degrees).
DEFAULT_FOV = 180.0
#: COLMAP's fisheye models -> (focal count, number of k terms): ``[f | fx fy] cx cy k...``.
COLMAP_MODELS = {"OPENCV_FISHEYE": (2, 4), "SIMPLE_RADIAL_FISHEYE": (1, 1), "RADIAL_FISHEYE": (1, 2)}


def fisheye_theta_d(theta: np.ndarray, k: tuple[float, float, float, float]) -> np.ndarray:
    """OpenCV fisheye ``theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)``."""
    t2 = theta * theta
    return theta * (1 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3]))))


def fisheye_theta_d_prime(theta: np.ndarray, k: tuple[float, float, float, float]) -> np.ndarray:
    """Derivative ``d theta_d / d theta = 1 + 3 k1 theta^2 + 5 k2 theta^4 + 7 k3 theta^6 + 9 k4 theta^8``."""
    t2 = theta * theta
    return 1 + t2 * (3 * k[0] + t2 * (5 * k[1] + t2 * (7 * k[2] + t2 * 9 * k[3])))


def fisheye_theta_limit(camera: "Camera") -> float:
    """Largest angle from the optical axis (radians) at which a fisheye keeps splat centres.

    The image corner farthest from the principal point, in normalised units, is a distorted
    angle ``theta_d``; the smallest ``theta`` that reaches it (on a 1e-4 rad grid, refined by
    bisection) plus :data:`FISHEYE_THETA_MARGIN`, capped at :data:`FISHEYE_THETA_CAP`.
    """
    k = camera.model.k
    corners_u = np.array([0.0, camera.width]) - camera.cx
    corners_v = np.array([0.0, camera.height]) - camera.cy
    r_max = math.sqrt(np.max(corners_u ** 2) / camera.fx ** 2 + np.max(corners_v ** 2) / camera.fy ** 2)
    grid = np.linspace(0.0, math.pi, 31417)
    reach = np.flatnonzero(fisheye_theta_d(grid, k) >= r_max)
    if reach.size == 0:
        theta = math.pi
    else:
        hi = grid[reach[0]]
        lo = grid[max(reach[0] - 1, 0)]
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            if fisheye_theta_d(np.float64(mid), k) >= r_max:
                hi = mid
            else:
                lo = mid
        theta = hi
    return float(min(theta + FISHEYE_THETA_MARGIN, FISHEYE_THETA_CAP))


def _fisheye_s_c2(p: np.ndarray, k) -> tuple[np.ndarray, ...]:
    """``(rho, theta, s, c2, g', R^2)`` of the fisheye map (series near the axis)."""
    dt = p.dtype.type
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    rho2 = x * x + y * y
    rho = np.sqrt(rho2)
    r2 = rho2 + z * z
    theta = np.arctan2(rho, z)
    g = fisheye_theta_d(theta, k)
    gp = fisheye_theta_d_prime(theta, k)
    near_axis = rho < dt(FISHEYE_SERIES_RHO) * z
    with np.errstate(divide="ignore", invalid="ignore"):
        s_far = g / rho
        c2_far = (gp * z / r2 - s_far) / rho2
        zs = np.where(near_axis, z, dt(1.0))
        t = rho2 / (zs * zs)
        s_near = (dt(1.0) + (dt(k[0]) - dt(1.0 / 3.0)) * t) / zs
        c2_near = (dt(2.0) * dt(k[0]) - dt(2.0 / 3.0)) / (zs * zs * zs)
    return (rho, theta, np.where(near_axis, s_near, s_far), np.where(near_axis, c2_near, c2_far),
            gp, r2)


@dataclass(frozen=True)
class Fisheye(LensDistortion):
    """``k``: the distortion coefficients k1..k4 of ``theta_d`` (zeros: equidistant)."""

    k: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)

    name: ClassVar[str] = "fisheye"
    cull: ClassVar[CullKind] = CullKind.SPHERE
    summary: ClassVar[str] = ("OpenCV's fisheye model, equidistant by default (--fov: the image "
                              "circle's field of view, default 180, up to 360)")
    colmap_names: ClassVar[tuple[str, ...]] = tuple(COLMAP_MODELS)
    transforms_names: ClassVar[tuple[str, ...]] = ("OPENCV_FISHEYE",)
    transforms_fields: ClassVar[tuple[str, ...]] = ("k1", "k2", "k3", "k4")

    def __post_init__(self) -> None:
        k = tuple(float(v) for v in self.k)
        if len(k) != 4 or not all(math.isfinite(v) for v in k):
            raise CameraError(f"camera distortion must be 4 finite numbers (k1..k4), got {self.k!r}")
        object.__setattr__(self, "k", k)

    def project(self, p_cam: np.ndarray, camera: "Camera") -> np.ndarray:
        dt = p_cam.dtype.type
        fx, fy, cx, cy = (dt(v) for v in (camera.fx, camera.fy, camera.cx, camera.cy))
        _, _, s, _, _, _ = _fisheye_s_c2(p_cam, self.k)
        return np.stack([fx * s * p_cam[:, 0] + cx, fy * s * p_cam[:, 1] + cy], -1)

    def jacobian(self, p_cam: np.ndarray, camera: "Camera") -> np.ndarray:
        dt = p_cam.dtype.type
        fx, fy = dt(camera.fx), dt(camera.fy)
        x, y = p_cam[:, 0], p_cam[:, 1]
        j = np.zeros((p_cam.shape[0], 2, 3), p_cam.dtype)
        _, _, s, c2, gp, r2 = _fisheye_s_c2(p_cam, self.k)
        j[:, 0, 0] = fx * (s + x * x * c2)
        j[:, 0, 1] = fx * x * y * c2
        j[:, 0, 2] = -fx * x * gp / r2
        j[:, 1, 0] = fy * x * y * c2
        j[:, 1, 1] = fy * (s + y * y * c2)
        j[:, 1, 2] = -fy * y * gp / r2
        return j

    def depth(self, p_cam: np.ndarray) -> np.ndarray:
        return np.sqrt(np.einsum("ni,ni->n", p_cam, p_cam))

    def visible(self, p_cam: np.ndarray, camera: "Camera", near) -> np.ndarray:
        dt = p_cam.dtype.type
        keep = self.depth(p_cam) > near
        rho = np.hypot(p_cam[:, 0], p_cam[:, 1])
        return keep & (np.arctan2(rho, p_cam[:, 2]) <= dt(fisheye_theta_limit(camera)))

    def angle_limit(self, camera: "Camera") -> float:
        return fisheye_theta_limit(camera)

    def defines(self) -> dict[str, object]:
        return {**super().defines(), "FISHEYE": 1}

    def uniforms(self, camera: "Camera") -> dict[str, object]:
        return {"u_distortion": self.k, "u_theta_limit": fisheye_theta_limit(camera)}

    @classmethod
    def intrinsics(cls, width, height, fov_degrees, like=None, k=(0.0, 0.0, 0.0, 0.0)):
        """A fisheye whose image circle of diameter ``min(W, H)`` spans ``fov_degrees`` (any
        angle up to 360; default 180), centred; with distortion ``k``, ``theta_d`` of the half
        angle is what reaches the circle's edge."""
        fov = DEFAULT_FOV if fov_degrees is None else fov_degrees
        if not 0.0 < fov <= 360.0:
            raise CameraError(f"fisheye field of view must be in (0, 360] degrees, got {fov}")
        half = math.radians(fov) / 2.0
        k1, k2, k3, k4 = (float(v) for v in k)
        theta_d = half * (1 + k1 * half ** 2 + k2 * half ** 4 + k3 * half ** 6 + k4 * half ** 8)
        if not theta_d > 0.0:
            raise CameraError(f"fisheye distortion {tuple(k)} maps the half angle to {theta_d}")
        f = 0.5 * min(width, height) / theta_d
        return f, f, width / 2.0, height / 2.0, cls((k1, k2, k3, k4))

    @classmethod
    def fov_range(cls):
        return (0.0, 360.0, True)

    def to_json(self) -> dict[str, object]:
        return {"distortion": list(self.k)} if any(self.k) else {}

    @classmethod
    def from_json(cls, obj: dict, path, where: str = "") -> "Fisheye":
        from .json_fields import matrix

        if "distortion" not in obj:
            return cls()
        k = obj["distortion"]
        if not isinstance(k, list) or len(k) != 4:
            got = len(k) if isinstance(k, list) else repr(k)
            raise CameraError(f"{path}: {where}field 'distortion' must be a list of 4 numbers "
                              f"(OpenCV's fisheye k1 k2 k3 k4), got {got}")
        return cls(tuple(matrix(path, where, {"distortion": k}, "distortion", (4,))))

    @classmethod
    def from_colmap(cls, name, params):
        focals, n_k = COLMAP_MODELS[name]
        k = tuple(params[2 + focals:2 + focals + n_k])
        return (*colmap_intrinsics(params, focals), cls(k + (0.0,) * (4 - n_k)))

    def to_colmap(self, camera):
        return "OPENCV_FISHEYE", (camera.fx, camera.fy, camera.cx, camera.cy, *self.k)

    @classmethod
    def from_transforms(cls, name, fields):
        """nerfstudio's OPENCV_FISHEYE: ``k1..k4`` are this model's (absent: 0)."""
        return cls(tuple(fields[k] or 0.0 for k in cls.transforms_fields))

    def to_transforms(self):
        return {"camera_model": "OPENCV_FISHEYE", **dict(zip(self.transforms_fields, self.k))}
