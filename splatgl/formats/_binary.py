"""Small bounds-checked helpers shared by the binary scene loaders (compressed PLY, SPZ, ksplat).

Every helper raises :class:`~splatgl.errors.SceneFormatError` (never ``IndexError``,
``struct.error`` or a NumPy error) so a truncated or corrupted file always ends in one clear
message that says what was expected and what was found.
"""

from __future__ import annotations

import json
import os
import struct
from pathlib import Path

import numpy as np

from ..constants import MAX_LOGIT, MIN_SCALE  # noqa: F401 (re-exported to the loaders)
from ..errors import SceneFormatError
from ..scene.json_text import unique_keys
from ._memory import require



def read_bytes(path: Path) -> bytes:
    """The whole file as bytes (refused when it cannot fit in memory); OS errors become
    :class:`SceneFormatError`."""
    try:
        with open(path, "rb") as fh:
            size = os.fstat(fh.fileno()).st_size
            require(path, size, f"the file ({size} bytes) is read whole and needs")
            return fh.read()
    except OSError as exc:
        raise SceneFormatError(path, f"cannot read: {exc.strerror or exc}") from None


def json_object(path: Path, name: str) -> dict:
    """The JSON object of the file ``path`` (``name``: what messages call it, ``meta.lcc``),
    duplicate keys refused; anything else is a :class:`SceneFormatError`."""
    try:
        meta = json.loads(read_bytes(path).decode("utf-8"), object_pairs_hook=unique_keys)
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise SceneFormatError(path, f"{name} is not valid JSON: {str(exc)[:100]}") from None
    if not isinstance(meta, dict):
        raise SceneFormatError(path, f"{name} is not a JSON object")
    return meta


def need(path, data: bytes, offset: int, size: int, what: str, field: str | None = None) -> None:
    """Raise unless ``data[offset:offset + size]`` lies wholly inside ``data``.

    The message names ``what`` was being read, the bytes expected and the bytes found.
    """
    have = max(0, len(data) - offset)
    if offset < 0 or size < 0 or size > have:
        raise SceneFormatError(
            path, f"truncated: {what} needs {size} bytes at offset {offset}, "
            f"but only {have} remain (file or stream is {len(data)} bytes)", field)


def unpack(path, fmt: str, data: bytes, offset: int, what: str) -> tuple:
    """``struct.unpack_from(fmt, data, offset)`` after a bounds check."""
    need(path, data, offset, struct.calcsize(fmt), what)
    return struct.unpack_from(fmt, data, offset)


def array(path, data: bytes, offset: int, dtype, count: int, what: str,
          field: str | None = None) -> np.ndarray:
    """A read-only view of ``count`` items of ``dtype`` at ``offset`` (bounds-checked, no copy)."""
    dtype = np.dtype(dtype)
    need(path, data, offset, count * dtype.itemsize, what, field)
    return np.frombuffer(data, dtype=dtype, count=count, offset=offset)


def check_fits(path, count: int, item_bytes: int, available: int, what: str,
               field: str | None = None) -> int:
    """Check that ``count`` items of ``item_bytes`` fit in ``available`` bytes; return the size.

    Call this with header counts *before* allocating anything sized by them, so a corrupted
    count fails at once instead of asking for terabytes.
    """
    size = count * item_bytes
    if count < 0 or size > available:
        raise SceneFormatError(
            path, f"truncated: {what} needs {count} x {item_bytes} = {size} bytes, "
            f"but only {available} remain", field)
    return size


def logit(p: np.ndarray) -> np.ndarray:
    """float32 ``log(p / (1 - p))`` of opacities ``p`` in [0, 1], clamped to +-MAX_LOGIT."""
    p = np.asarray(p, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.log(p) - np.log1p(-p)
    return np.clip(out, -MAX_LOGIT, MAX_LOGIT).astype(np.float32)


def unorm(value: np.ndarray, shift: int, bits: int) -> np.ndarray:
    """float64 unsigned-normalised field ``((value >> shift) & (2^bits - 1)) / (2^bits - 1)``."""
    mask = (1 << bits) - 1
    return ((np.asarray(value, np.uint32) >> np.uint32(shift)) & np.uint32(mask)) / float(mask)


def log_of(values: np.ndarray) -> np.ndarray:
    """float32 natural log of linear scales; exact zeros are floored to MIN_SCALE.

    Negative scales give NaN, which :func:`~splatgl.scene.splats.activate` rejects (or drops).
    """
    v = np.asarray(values, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.log(np.where(v == 0.0, MIN_SCALE, v)).astype(np.float32)
