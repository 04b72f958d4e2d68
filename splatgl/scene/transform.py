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
import numbers
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


def _finite_array(value, shape: tuple) -> np.ndarray | None:
    """``value`` as a float64 array if it is nested lists, tuples or arrays of exactly ``shape``
    holding finite real numbers; else None.  Booleans and strings are not numbers here (NumPy
    would read ``true`` as 1 and ``"1"`` as 1.0, hiding a mistake)."""
    def fits(v, dims: tuple) -> bool:
        if not dims:
            if isinstance(v, (bool, np.bool_)) or not isinstance(v, numbers.Real):
                return False
            try:
                return math.isfinite(v)
            except OverflowError:   # an integer beyond float64
                return False
        if isinstance(v, np.ndarray) and v.ndim == 0 or not isinstance(v, (list, tuple, np.ndarray)):
            return False
        return len(v) == dims[0] and all(fits(x, dims[1:]) for x in v)
    return np.asarray(value, np.float64) if fits(value, tuple(shape)) else None


def _is_rotation(r: np.ndarray) -> bool:
    """``r`` (3x3) is orthonormal with determinant +1 (no mirroring, no scale)."""
    return bool(np.allclose(r @ r.T, np.eye(3), atol=1e-6) and np.linalg.det(r) > 0)


#: The longest value a message quotes in full.
SHOWN_CHARS = 80


def _shown(value, as_json: bool = False) -> str:
    """``value`` on one line for a message: as JSON (what a ``--transform`` user typed) or as
    Python writes it, cut to :data:`SHOWN_CHARS`."""
    if isinstance(value, np.ndarray):
        value = value.tolist()
    try:
        text = json.dumps(value) if as_json else repr(value)
    except (TypeError, ValueError):
        text = repr(value)
    text = " ".join(text.split())
    return text if len(text) <= SHOWN_CHARS else text[:SHOWN_CHARS - 3] + "..."


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
        r = _finite_array(self.rotation, (3, 3))
        t = _finite_array(self.translation, (3,))
        if r is None:
            raise SplatglError(f"transform rotation must be a 3x3 matrix of finite numbers, got "
                               f"{_shown(self.rotation)}")
        if not _is_rotation(r):
            raise SplatglError("transform rotation must be a proper rotation (orthonormal, det +1), "
                               f"got {_shown(self.rotation)}")
        if t is None:
            raise SplatglError("transform translation must be 3 finite numbers, got "
                               f"{_shown(self.translation)}")
        if _finite_array(self.scale, ()) is None or not self.scale > 0:
            raise SplatglError(f"transform scale must be a positive finite number, got {_shown(self.scale)}")
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
    if not text.lstrip().startswith("{") and _is_file(text):
        try:
            source = Path(text).read_text()
        except (OSError, UnicodeDecodeError) as exc:
            raise SplatglError(f"{what}: cannot read {text}: {exc}") from None
    try:
        obj = json.loads(source, object_pairs_hook=unique_keys)
    except DuplicateKeyError as exc:
        raise SplatglError(f"{what}: {exc}: {_shown(text)}") from None
    except json.JSONDecodeError as exc:
        raise SplatglError(f"{what}: not JSON or a JSON file ({exc.msg} at column {exc.colno}): "
                           f"{_shown(text)}") from None
    except RecursionError:
        raise SplatglError(f"{what}: not JSON (nested too deeply)") from None
    return transform_from_object(obj, what)


def _is_file(text: str) -> bool:
    """``text`` names an existing file (a name the system refuses, too long or holding a NUL,
    names none)."""
    try:
        return Path(text).is_file()
    except (OSError, ValueError):
        return False


#: Each key of a transform object: the shape of its value and what it must be, for messages.
TRANSFORM_KEYS = {
    "rotate_deg": ((3,), "3 finite numbers (degrees)"),
    "rotation": ((3, 3), "a 3x3 rotation matrix (3 rows of 3 finite numbers)"),
    "translate": ((3,), "3 finite numbers"),
    "scale": ((), "a positive finite number"),
}


def transform_from_object(obj, what: str = "--transform") -> SceneTransform:
    """A transform from a parsed JSON object (:func:`parse_transform`'s keys).  Each refused
    value is one :class:`SplatglError` line naming ``what``, the key and the value as JSON."""
    if not isinstance(obj, dict):
        raise SplatglError(f"{what}: expected a JSON object with keys {', '.join(TRANSFORM_KEYS)}, "
                           f"got {_shown(obj, True)}")
    unknown = set(obj) - set(TRANSFORM_KEYS)
    if unknown:
        raise SplatglError(f"{what}: unknown key(s) {sorted(unknown)} (use {', '.join(TRANSFORM_KEYS)})")
    if "rotation" in obj and "rotate_deg" in obj:
        raise SplatglError(f"{what}: give either 'rotate_deg' or 'rotation', not both "
                           "(one would be ignored)")
    values = {}
    for key, value in obj.items():
        shape, need = TRANSFORM_KEYS[key]
        values[key] = _finite_array(value, shape)
        if values[key] is None or key == "scale" and not values[key] > 0:
            raise SplatglError(f"{what}: {key} must be {need}, got {_shown(value, True)}")
    if "rotation" in values and not _is_rotation(values["rotation"]):
        raise SplatglError(f"{what}: rotation must be a proper rotation matrix (orthonormal, "
                           f"det +1), got {_shown(obj['rotation'], True)}")
    rotation = values["rotation"] if "rotation" in values else _euler_xyz(values.get("rotate_deg", (0, 0, 0)))
    return SceneTransform(tuple(map(tuple, rotation)), tuple(values.get("translate", (0.0, 0.0, 0.0))),
                          float(values.get("scale", 1.0)))
