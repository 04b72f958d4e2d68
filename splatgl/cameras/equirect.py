"""The equirectangular camera: a longitude/latitude panorama, and omni-directional stereo.

Shader piece: ``shaders/cameras/equirect.glsl`` (same names).  Camera space, OpenCV axes:
``lon = atan2(x, z)``, ``lat = atan2(y, r)`` (positive below the horizon) with
``r = sqrt(x^2 + z^2)``, ``u = fx lon + cx``, ``v = fy lat + cy``; a full panorama has
``fx = W / 2 pi``, ``fy = H / pi`` and the principal point at the image centre.
``J = [[fx z / r^2, 0, -fx x / r^2], [-fy x y / (R^2 r), fy r / R^2, -fy z y / (R^2 r)]]``.

At the poles ``r -> 0`` and the longitude row grows without bound: every longitude is within
reach.  ``r`` is floored at ``EQUIRECT_POLE_EPS R`` (a finite, enormous width), and every splat
is clipped to half a turn on either side of its centre (:meth:`Equirectangular.seam_period`), so
a splat at a pole becomes a band across the whole image, once.  A splat near the +-180 degree
seam is drawn twice, at ``u`` and at ``u -+ 2 pi fx`` (:func:`wrap_copies`); with the half-turn
clip the two copies never cover the same pixel.  It culls and sorts by distance, as the fisheye.

Omni-directional stereo (``ods_eye`` != 0): each splat is seen from the point of the eye circle
whose tangent ray reaches it (:func:`eye_space`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from ..constants import EQUIRECT_POLE_EPS
from ..errors import CameraError
from .model import CameraModel, CullKind

if TYPE_CHECKING:
    from .camera import Camera

#: Screen margin (pixels) of the seam test: a splat whose reach comes this close to the seam is
#: drawn on both sides.
SEAM_MARGIN_PX = 4.0
#: Top bit of a sorted index: the entry is the second copy of a seam splat (``shaders/lib/
#: splat_setup.glsl`` decodes it).
WRAP_FLAG = np.uint32(0x80000000)


def eye_space(p_cam: np.ndarray, camera: "Camera") -> np.ndarray:
    """Omni-directional stereo: (N, 3) points relative to the eye that sees each of them.

    The eyes sit on a circle of radius ``r = |ods_eye|`` in the camera's horizontal (x, z)
    plane.  A point at horizontal distance ``D`` and longitude ``a`` is seen along the ray
    tangent to that circle, of longitude ``phi = a - asin(ods_eye / D)``, from the eye
    ``e = ods_eye (cos phi, 0, -sin phi)`` (``p - e`` then has longitude ``phi``; points inside
    the circle, ``D <= r``, are seen from the tangent point at ``D = r``).  The offset is taken
    at the splat's centre and held constant across the splat.  No-op for other cameras and for
    a mono panorama.
    """
    eye = getattr(camera.model, "ods_eye", 0.0)
    if not eye:
        return p_cam
    dt = p_cam.dtype.type
    x, z = p_cam[:, 0], p_cam[:, 2]
    d = np.maximum(np.sqrt(x * x + z * z), dt(abs(eye)))
    phi = np.arctan2(x, z) - np.arcsin(dt(eye) / d)
    out = p_cam.copy()
    out[:, 0] -= dt(eye) * np.cos(phi)
    out[:, 2] += dt(eye) * np.sin(phi)
    return out


def wrap_copies(p_cam: np.ndarray, radius: np.ndarray, camera: "Camera") -> np.ndarray:
    """(N,) bool: splats that may reach across the +-180 degree seam (drawn twice).

    The seam is the half plane ``x = 0, z < 0``.  A splat of world radius ``radius`` (its
    opacity-aware reach plus a pixel margin) can touch it only if ``|x| < radius`` and
    ``z < radius``; that bound also holds every splat near a pole.  All False for models
    without a seam.
    """
    if camera.model.seam_period(camera) is None:
        return np.zeros(p_cam.shape[0], bool)
    dist = np.sqrt(np.einsum("ni,ni->n", p_cam, p_cam).astype(np.float64))
    reach = radius.astype(np.float64) + SEAM_MARGIN_PX * dist / camera.fx
    return (np.abs(p_cam[:, 0]) < reach) & (p_cam[:, 2] < reach)


def wrap_shift(mean_u: np.ndarray, camera: "Camera") -> np.ndarray:
    """(N,) shift in pixels of the second copy of a seam splat: towards the other edge."""
    period = camera.model.seam_period(camera)
    return np.where(mean_u < camera.cx, period, -period).astype(mean_u.dtype)


@dataclass(frozen=True)
class Equirectangular(CameraModel):
    """``ods_eye``: signed eye offset (world units, -IPD/2 for the left eye, +IPD/2 for the
    right) of omni-directional stereo; 0 for a mono panorama."""

    ods_eye: float = 0.0

    name: ClassVar[str] = "equirectangular"
    json_fields: ClassVar[tuple[str, ...]] = ("ods_eye",)
    glsl: ClassVar[str] = "equirect"
    cull: ClassVar[CullKind] = CullKind.SPHERE
    draws_surfels: ClassVar[bool] = False
    intrinsics_optional: ClassVar[bool] = True
    no_fov: ClassVar[str] = "an equirectangular panorama always spans 360 x 180 degrees"
    aspect: ClassVar[float | None] = 2.0
    summary: ClassVar[str] = "a 360 x 180 degree panorama (usually --width = 2 x --height)"

    def __post_init__(self) -> None:
        ods = float(self.ods_eye)
        if not math.isfinite(ods):
            raise CameraError(f"an omni-directional stereo eye offset must be finite, got {self.ods_eye!r}")
        object.__setattr__(self, "ods_eye", ods)

    def project(self, p_cam: np.ndarray, camera: "Camera") -> np.ndarray:
        dt = p_cam.dtype.type
        fx, fy, cx, cy = (dt(v) for v in (camera.fx, camera.fy, camera.cx, camera.cy))
        x, y, z = p_cam[:, 0], p_cam[:, 1], p_cam[:, 2]
        r = np.sqrt(x * x + z * z)
        return np.stack([fx * np.arctan2(x, z) + cx, fy * np.arctan2(y, r) + cy], -1)

    def jacobian(self, p_cam: np.ndarray, camera: "Camera") -> np.ndarray:
        dt = p_cam.dtype.type
        fx, fy = dt(camera.fx), dt(camera.fy)
        x, y, z = p_cam[:, 0], p_cam[:, 1], p_cam[:, 2]
        j = np.zeros((p_cam.shape[0], 2, 3), p_cam.dtype)
        big_r2 = x * x + y * y + z * z
        r = np.maximum(np.sqrt(x * x + z * z), dt(EQUIRECT_POLE_EPS) * np.sqrt(big_r2))
        j[:, 0, 0] = fx * z / (r * r)
        j[:, 0, 2] = -fx * x / (r * r)
        j[:, 1, 0] = -fy * x * y / (big_r2 * r)
        j[:, 1, 1] = fy * r / big_r2
        j[:, 1, 2] = -fy * z * y / (big_r2 * r)
        return j

    def depth(self, p_cam: np.ndarray) -> np.ndarray:
        return np.sqrt(np.einsum("ni,ni->n", p_cam, p_cam))

    def visible(self, p_cam: np.ndarray, camera: "Camera", near) -> np.ndarray:
        return self.depth(p_cam) > near

    def seam_period(self, camera: "Camera") -> float:
        """Pixels per full turn of longitude (``2 pi fx``): every splat is clipped to
        ``|x - u| <= period / 2``."""
        return 2.0 * math.pi * camera.fx

    def eye_pair(self, camera, half_ipd):
        """Omni-directional stereo: the same panorama seen from eyes at -+``half_ipd`` on the
        eye circle (:func:`eye_space`)."""
        return camera.with_model(Equirectangular(-half_ipd)), camera.with_model(Equirectangular(half_ipd))

    def defines(self) -> dict[str, object]:
        return {**super().defines(), "EQUIRECT": 1}

    def uniforms(self, camera: "Camera") -> dict[str, object]:
        return {"u_wrap_period": self.seam_period(camera), "u_ods_eye": self.ods_eye}

    @classmethod
    def intrinsics(cls, width, height, fov_degrees, like=None):
        """The full 360 x 180 degree panorama (``fov_degrees`` does not apply)."""
        return width / (2.0 * math.pi), height / math.pi, width / 2.0, height / 2.0, cls()

    def to_json(self) -> dict[str, object]:
        return {"ods_eye": self.ods_eye} if self.ods_eye else {}

    @classmethod
    def from_json(cls, obj: dict, path, where: str = "") -> "Equirectangular":
        from .json_fields import number

        return cls(number(path, where, obj, "ods_eye")) if "ods_eye" in obj else cls()
