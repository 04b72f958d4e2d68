"""Small JSON helpers shared by every camera loader (camera files, datasets, camera paths):
read a file, fetch typed fields with errors that name the file, the entry and the field."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ..errors import CameraError
from ..scene.json_text import DuplicateKeyError, unique_keys


def read_json(path: Path, what: str = "file") -> object:
    """The parsed JSON of ``path``; a one-line CameraError naming it (as ``what``) otherwise,
    also for a key repeated in one object (:func:`splatgl.scene.json_text.unique_keys`: JSON
    would keep the last without a word).  Every user JSON file splatgl reads for cameras
    (camera files, cameras.json, datasets' transforms.json, camera paths) comes through here."""
    try:
        return json.loads(Path(path).read_text(), object_pairs_hook=unique_keys)
    except DuplicateKeyError as exc:
        raise CameraError(f"{path}: {exc}") from None
    except RecursionError:
        raise CameraError(f"{path}: not valid JSON (nested too deeply)") from None
    except FileNotFoundError:
        raise CameraError(f"{path}: no such {what}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise CameraError(f"{path}: cannot read {what} ({exc})") from None
    except json.JSONDecodeError as exc:
        raise CameraError(f"{path}: not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})") from None


def number(path: Path, where: str, obj: dict, key: str, default: float | None = None,
           positive: bool = False) -> float:
    """``obj[key]`` as a finite float (``default`` when absent and given)."""
    if key not in obj:
        if default is not None:
            return default
        raise CameraError(f"{path}: {where}missing field '{key}'")
    value = obj[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise CameraError(f"{path}: {where}field '{key}' must be a finite number, got {value!r}")
    if positive and not value > 0:
        raise CameraError(f"{path}: {where}field '{key}' must be positive, got {value!r}")
    return float(value)


def matrix(path: Path, where: str, obj: dict, key: str, shape: tuple[int, ...],
           flat: bool = True) -> np.ndarray:
    """``obj[key]`` as a finite float64 array of ``shape``; with ``flat``, a flat list of the
    same size is reshaped row-major (as nerfstudio's camera paths store 4x4 matrices).  The
    error says what is wrong: not numbers, the shape, or which entry is NaN or Inf."""
    if key not in obj:
        raise CameraError(f"{path}: {where}missing field '{key}'")
    size = f"a {shape[0]}x{shape[1]} array" if len(shape) == 2 else f"{shape[0]} numbers"
    try:
        arr = np.array(obj[key], dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        of_numbers = f"{size} of numbers" if len(shape) == 2 else size
        raise CameraError(f"{path}: {where}field '{key}' must be {of_numbers}") from None
    if flat and arr.shape != shape and arr.size == int(np.prod(shape)) and arr.ndim == 1:
        arr = arr.reshape(shape)
    if arr.shape != shape:
        raise CameraError(f"{path}: {where}field '{key}' must be {size}, got shape {arr.shape}")
    bad = np.argwhere(~np.isfinite(arr))
    if len(bad):
        idx = tuple(int(v) for v in bad[0])
        value = "NaN" if np.isnan(arr[idx]) else "Inf"
        at = f"row {idx[0]}, column {idx[1]}" if len(idx) == 2 else f"entry {idx[0]}"
        raise CameraError(f"{path}: {where}field '{key}' holds {value} at {at}")
    return arr


def entries(path: Path, obj: dict, key: str) -> list:
    """``obj[key]`` as a non-empty list."""
    value = obj.get(key) if isinstance(obj, dict) else None
    if not isinstance(value, list) or not value:
        raise CameraError(f"{path}: field '{key}' must be a non-empty list")
    return value
