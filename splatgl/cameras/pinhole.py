"""The pinhole (perspective) camera: ``u = fx x / z + cx``, ``v = fy y / z + cy``.

Shader piece: ``shaders/cameras/pinhole.glsl`` (same names).  EWA's Jacobian is
``[[fx/z, 0, -fx x/z^2], [0, fy/z, -fy y/z^2]]`` with ``x/z`` and ``y/z`` clamped to
+-JACOBIAN_CLAMP tan(half fov) inside the Jacobian only (the reference's rule; the mean is not
moved).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from ..constants import JACOBIAN_CLAMP
from ..errors import CameraError
from .model import CameraModel, CullKind

if TYPE_CHECKING:
    from .camera import Camera

#: Vertical field of view of a perspective camera made without one (degrees).
DEFAULT_FOV = 50.0


@dataclass(frozen=True)
class Pinhole(CameraModel):
    name: ClassVar[str] = "perspective"
    glsl: ClassVar[str] = "pinhole"
    cull: ClassVar[CullKind] = CullKind.FRUSTUM
    summary: ClassVar[str] = "pinhole camera (--fov: vertical field of view, default 50)"

    def project(self, p_cam: np.ndarray, camera: "Camera") -> np.ndarray:
        fx, fy, cx, cy = (np.asarray(v, p_cam.dtype) for v in (camera.fx, camera.fy, camera.cx, camera.cy))
        return np.stack([fx * p_cam[:, 0] / p_cam[:, 2] + cx, fy * p_cam[:, 1] / p_cam[:, 2] + cy], -1)

    def jacobian(self, p_cam: np.ndarray, camera: "Camera") -> np.ndarray:
        dtype = p_cam.dtype
        j = np.zeros((p_cam.shape[0], 2, 3), dtype)
        tx, ty = camera.tan_half_fov
        z = p_cam[:, 2]
        limx, limy = dtype.type(JACOBIAN_CLAMP * tx), dtype.type(JACOBIAN_CLAMP * ty)
        xz = np.clip(p_cam[:, 0] / z, -limx, limx)
        yz = np.clip(p_cam[:, 1] / z, -limy, limy)
        fx, fy = dtype.type(camera.fx), dtype.type(camera.fy)
        j[:, 0, 0] = fx / z
        j[:, 0, 2] = -fx * xz / z
        j[:, 1, 1] = fy / z
        j[:, 1, 2] = -fy * yz / z
        return j

    @classmethod
    def intrinsics(cls, width, height, fov_degrees, like=None):
        """Square pixels, centred, vertical field of view ``fov_degrees`` (default 50; without
        one, a perspective ``like`` keeps its own intrinsics)."""
        if fov_degrees is None and like is not None and isinstance(like.model, Pinhole):
            return like.fx, like.fy, like.cx, like.cy, like.model
        fov = DEFAULT_FOV if fov_degrees is None else fov_degrees
        if not 0.0 < fov < 180.0:
            raise CameraError(f"field of view must be in (0, 180) degrees, got {fov}")
        f = 0.5 * height / math.tan(math.radians(fov) / 2.0)
        return f, f, width / 2.0, height / 2.0, cls()

    @classmethod
    def fov_range(cls):
        return (0.0, 180.0, False)
