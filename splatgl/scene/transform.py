"""Placing a scene in the world: rotation, translation and uniform scale (a scene transform).

A transform maps scene coordinates to world coordinates, ``p_w = s R p + t``.  Rendering folds
it into the camera (:func:`apply_transform`): the camera's matrix becomes scene-to-camera,
``W M``.  Every path then projects means and covariances with it unchanged (the covariance
picks up ``s^2 R Sigma R^T`` through ``J W M``), and the camera centre computed from that
matrix lies in the scene's own frame, so SH is evaluated with the view direction rotated back
into the scene's frame (DESIGN.md section 1), never with the world-space direction.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import SplatglError


def _euler_xyz(degrees) -> np.ndarray:
    """Rotation matrix for rotations about x, then y, then z (extrinsic), in degrees."""
    rx, ry, rz = (math.radians(float(a)) for a in degrees)
    cx, sx, cy, sy, cz, sz = math.cos(rx), math.sin(rx), math.cos(ry), math.sin(ry), math.cos(rz), math.sin(rz)
    mx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    my = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    mz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return mz @ my @ mx


@dataclass(frozen=True)
class SceneTransform:
    """Scene-to-world transform ``p_w = scale * rotation @ p + translation``.

    Attributes (tuples, so settings holding a transform stay hashable):
        rotation: 3x3 rotation, row-major nested tuples.
        translation: (tx, ty, tz) world units.
        scale: uniform scale > 0.
    """

    rotation: tuple = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    translation: tuple = (0.0, 0.0, 0.0)
    scale: float = 1.0

    def __post_init__(self) -> None:
        r = np.asarray(self.rotation, np.float64)
        t = np.asarray(self.translation, np.float64)
        if r.shape != (3, 3) or not np.isfinite(r).all():
            raise SplatglError(f"transform rotation must be a finite 3x3 matrix, got shape {r.shape}")
        if not np.allclose(r @ r.T, np.eye(3), atol=1e-6) or np.linalg.det(r) < 0:
            raise SplatglError("transform rotation must be a proper rotation (orthonormal, det +1)")
        if t.shape != (3,) or not np.isfinite(t).all():
            raise SplatglError(f"transform translation must be 3 finite numbers, got {self.translation!r}")
        if not (math.isfinite(self.scale) and self.scale > 0):
            raise SplatglError(f"transform scale must be positive, got {self.scale!r}")
        object.__setattr__(self, "rotation", tuple(tuple(float(v) for v in row) for row in r))
        object.__setattr__(self, "translation", tuple(float(v) for v in t))
        object.__setattr__(self, "scale", float(self.scale))

    @classmethod
    def from_euler(cls, degrees=(0.0, 0.0, 0.0), translation=(0.0, 0.0, 0.0), scale: float = 1.0) -> "SceneTransform":
        """Rotation about x, then y, then z by ``degrees``; then scale and translation."""
        return cls(tuple(map(tuple, _euler_xyz(degrees))), tuple(translation), scale)

    @property
    def matrix(self) -> np.ndarray:
        """(4, 4) float64 scene-to-world matrix."""
        m = np.eye(4)
        m[:3, :3] = self.scale * np.asarray(self.rotation)
        m[:3, 3] = self.translation
        return m

    @property
    def is_identity(self) -> bool:
        return np.array_equal(self.matrix, np.eye(4))

    def apply_points(self, points: np.ndarray) -> np.ndarray:
        """World positions (N, 3) of scene points (N, 3), float64."""
        return self.scale * np.asarray(points, np.float64) @ np.asarray(self.rotation).T + self.translation


def parse_transform(text: str, what: str = "--transform") -> SceneTransform:
    """A transform from inline JSON or a JSON file: ``{"rotate_deg": [rx, ry, rz] or
    "rotation": 3x3, "translate": [x, y, z], "scale": s}`` (all keys optional; a key repeated
    in the object is refused).  ``what`` names the option in messages."""
    from .json_text import DuplicateKeyError, unique_keys

    source = text
    path = Path(text)
    if not text.lstrip().startswith("{") and path.is_file():
        source = path.read_text()
    try:
        obj = json.loads(source, object_pairs_hook=unique_keys)
    except DuplicateKeyError as exc:
        raise SplatglError(f"{what}: {exc}: {text!r}") from None
    except json.JSONDecodeError as exc:
        raise SplatglError(f"{what}: not JSON or a JSON file ({exc.msg} at column {exc.colno}): {text!r}") from None
    return transform_from_object(obj, what)


def transform_from_object(obj, what: str = "--transform") -> SceneTransform:
    """A transform from a parsed JSON object (:func:`parse_transform`'s keys)."""
    if not isinstance(obj, dict):
        raise SplatglError(f"{what}: expected a JSON object")
    unknown = set(obj) - {"rotate_deg", "rotation", "translate", "scale"}
    if unknown:
        raise SplatglError(f"{what}: unknown key(s) {sorted(unknown)} (use rotate_deg, rotation, translate, scale)")
    if "rotation" in obj and "rotate_deg" in obj:
        raise SplatglError(f"{what}: give either 'rotate_deg' or 'rotation', not both "
                           "(one would be ignored)")
    try:
        if "rotation" in obj:
            rot = tuple(map(tuple, np.asarray(obj["rotation"], np.float64)))
        else:
            rot = tuple(map(tuple, _euler_xyz(obj.get("rotate_deg", (0, 0, 0)))))
        return SceneTransform(rot, tuple(obj.get("translate", (0.0, 0.0, 0.0))), float(obj.get("scale", 1.0)))
    except (TypeError, ValueError, OverflowError) as exc:
        raise SplatglError(f"{what}: {exc}") from None
