"""The orthographic camera: ``u = fx x + cx``, ``v = fy y + cy`` (fx, fy in pixels per world unit).

Shader piece: ``shaders/cameras/orthographic.glsl``.  Its Jacobian is the constant
``diag(fx, fy)``; every pixel's ray has the same direction (+z), which 2DGS surfels and the
order stage's box cull use.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from .model import CameraModel, CullKind

if TYPE_CHECKING:
    from .camera import Camera


@dataclass(frozen=True)
class Orthographic(CameraModel):
    name: ClassVar[str] = "orthographic"
    cull: ClassVar[CullKind] = CullKind.BOX
    parallel_rays: ClassVar[bool] = True
    summary: ClassVar[str] = "parallel projection (fx, fy in pixels per world unit)"
    no_fov: ClassVar[str] = "an orthographic camera has no field of view (its scale is pixels per world unit)"
    keeps_intrinsics: ClassVar[bool] = True

    def project(self, p_cam: np.ndarray, camera: "Camera") -> np.ndarray:
        fx, fy, cx, cy = (np.asarray(v, p_cam.dtype) for v in (camera.fx, camera.fy, camera.cx, camera.cy))
        return np.stack([fx * p_cam[:, 0] + cx, fy * p_cam[:, 1] + cy], axis=-1)

    def jacobian(self, p_cam: np.ndarray, camera: "Camera") -> np.ndarray:
        j = np.zeros((p_cam.shape[0], 2, 3), p_cam.dtype)
        j[:, 0, 0] = camera.fx
        j[:, 1, 1] = camera.fy
        return j

    def defines(self) -> dict[str, object]:
        return {**super().defines(), "ORTHOGRAPHIC": 1}

    @classmethod
    def intrinsics(cls, width, height, fov_degrees, like=None):
        """Keeps ``like``'s intrinsics as pixels per world unit; without one, 1 pixel per unit,
        centred (:func:`splatgl.api.default_camera` zooms it to frame a scene)."""
        if like is not None:
            return like.fx, like.fy, like.cx, like.cy, cls()
        return 1.0, 1.0, width / 2.0, height / 2.0, cls()
