"""The pinhole (perspective) camera: ``u = fx x / z + cx``, ``v = fy y / z + cy``.

Shader piece: ``shaders/cameras/pinhole.glsl`` (same names).  EWA's Jacobian is
``[[fx/z, 0, -fx x/z^2], [0, fy/z, -fy y/z^2]]`` with ``x/z`` and ``y/z`` clamped to
+-JACOBIAN_CLAMP tan(half fov) inside the Jacobian only (the reference's rule; the mean is not
moved).

Camera files: COLMAP's SIMPLE_PINHOLE ``(f, cx, cy)`` and PINHOLE ``(fx, fy, cx, cy)``, and the
models with distortion terms (SIMPLE_RADIAL, RADIAL, OPENCV, FULL_OPENCV) when every term is 0
(nonzero terms are refused by name unless a later model claims those names);
``transforms.json``'s OPENCV, PINHOLE and SIMPLE_PINHOLE without distortion fields.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from ..constants import JACOBIAN_CLAMP
from ..errors import CameraError
from .model import CameraModel, colmap_intrinsics

if TYPE_CHECKING:
    from .camera import Camera

#: Vertical field of view of a perspective camera made without one (degrees).
DEFAULT_FOV = 50.0
#: COLMAP models read as pinholes -> their focal count (1: ``f cx cy``, 2: ``fx fy cx cy``);
#: parameters after the principal point are distortion terms, which must all be 0.
COLMAP_FOCALS = {"SIMPLE_PINHOLE": 1, "PINHOLE": 2, "SIMPLE_RADIAL": 1, "RADIAL": 1, "OPENCV": 2,
                 "FULL_OPENCV": 2}


@dataclass(frozen=True)
class Pinhole(CameraModel):
    name: ClassVar[str] = "perspective"
    glsl: ClassVar[str] = "pinhole"
    summary: ClassVar[str] = "pinhole camera (--fov: vertical field of view, default 50)"
    colmap_names: ClassVar[tuple[str, ...]] = tuple(COLMAP_FOCALS)
    transforms_names: ClassVar[tuple[str, ...]] = ("OPENCV", "PINHOLE", "SIMPLE_PINHOLE")
    transforms_fields: ClassVar[tuple[str, ...]] = ("k1", "k2", "k3", "k4", "p1", "p2")

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

    @classmethod
    def from_colmap(cls, name, params):
        focals = COLMAP_FOCALS[name]
        terms = params[2 + focals:]
        if any(terms):
            raise CameraError(f"COLMAP model {name} has nonzero lens distortion "
                              f"({' '.join(f'{v:g}' for v in terms)}), which splatgl does not "
                              "render; undistort the images first (colmap image_undistorter)")
        return (*colmap_intrinsics(params, focals), cls())

    def to_colmap(self, camera):
        return "PINHOLE", (camera.fx, camera.fy, camera.cx, camera.cy)

    @classmethod
    def from_transforms(cls, name, fields):
        for key, value in fields.items():
            if value:
                raise CameraError(f"field '{key}' = {value}: lens distortion is not supported; "
                                  "undistort the images first")
        return cls()

    def to_transforms(self):
        return {"camera_model": "OPENCV"}
