"""XGrids LCC (``meta.lcc`` with ``Index.bin``, ``Data.bin``, optional ``Shcoef.bin`` and
``Environment.bin`` beside it): reader, after XGrids' public white paper
(github.com/xgrids/LCCWhitepaper).

- ``meta.lcc`` (JSON): ``totalLevel`` levels (level 0 the finest), ``splats`` per level,
  ``boundingBox`` and ``cellLengthX`` / ``cellLengthY`` (the grid of units), ``fileType``
  (``Portable``: no SH; ``Quality``: SH degree 3 in ``Shcoef.bin``; missing: SH when an
  ``shcoef`` attribute is listed), and ``attributes``: ``scale`` / ``shcoef`` (and ``envscale`` /
  ``envshcoef`` for the environment) ``min`` and ``max`` per axis, the ranges of the quantised
  values.
- ``Index.bin``: per unit (a grid cell), ``indexDataSize`` = 4 + 16 levels bytes: int16 x, int16
  y (its cell), then per level uint32 splats, uint64 byte offset into ``Data.bin``, uint32 bytes.
- ``Data.bin``: 32 bytes a splat, little-endian: float32 x, y, z; uint8 R, G, B (the colour,
  ``f_dc = (c / 255 - 0.5) / C0``) and opacity (``/ 255``); uint16 scale x, y, z (linear scales,
  ``min + (max - min) u / 65535``); uint32 rotation (three 10-bit components of the smallest
  three, ``c / 1023 * sqrt(2) - 1 / sqrt(2)``, and in bits 30-31 where the largest goes, as the
  white paper's ``QLut``); uint16 normal x, y, z (unused).
- ``Shcoef.bin``: 64 bytes a splat at twice the unit's ``Data.bin`` offset: 15 uint32 (the SH
  coefficients, red in bits 0-10, green 11-20, blue 21-31, ``min + (max - min) u / (2^bits - 1)``
  per channel of ``shcoef``), one unused.
- ``Environment.bin``: the environment's splats, ``Data.bin`` records each followed by the 64 SH
  bytes when the scene has SH; ranges ``envscale`` / ``envshcoef``.

LCC stores z-up axes; the reader turns them into PLY's (as splat-transform does: :data:`TO_PLY`),
positions, rotations and SH alike.  ``offset``, ``shift`` and ``scale`` (geo-referencing) are not
applied.  :func:`read_structure` reads ``meta.lcc`` and ``Index.bin`` only (levels, units with
their boxes: a streaming renderer's chunks); :meth:`Lcc.load` decodes a level or chosen units;
:func:`read` loads the finest level and the environment.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..constants import SH_C0
from ..errors import SceneFormatError
from ..scene.quaternion import quat_multiply, rotmat_to_quat
from ..scene.splats import Scene, activate
from ..splatmath.project import sh_basis
from . import _binary
from .streamed_sog import Chunk, concatenate

NAME = "lcc"
EXTENSIONS = (".lcc",)
#: LCC axes -> PLY axes (what splat-transform applies: its Euler angles (90, 0, 180) after PLY's
#: own turn, measured on files it converts).
TO_PLY = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # (x, -z, y)
RECORD = np.dtype([("pos", "<f4", 3), ("rgba", "u1", 4), ("scale", "<u2", 3), ("rot", "<u4"),
                   ("normal", "<u2", 3)])
SH_BYTES = 64
_QLUT = np.array([[3, 0, 1, 2], [0, 3, 1, 2], [0, 1, 3, 2], [0, 1, 2, 3]])


def sniff(head: bytes) -> bool:
    return head.lstrip().startswith(b"{") and b'"totalLevel"' in head


def _file(path: Path, name: str) -> Path | None:
    """``name`` beside ``path``, matched without regard to case (the white paper writes
    ``Data.bin``, tools often ``data.bin``); None when there is none."""
    folder = path.parent
    if (folder / name).is_file():
        return folder / name
    try:
        for entry in os.listdir(folder):
            if entry.lower() == name.lower() and (folder / entry).is_file():
                return folder / entry
    except OSError:
        pass
    return None


def _range(path, attrs: dict, name: str, fallback: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    attr = attrs.get(name) or (attrs.get(fallback) if fallback else None)
    if attr is None:
        raise SceneFormatError(path, f"no '{name}' attribute (min, max)", "attributes")
    try:
        lo = np.asarray(attr["min"], np.float64)
        hi = np.asarray(attr["max"], np.float64)
    except (TypeError, KeyError, ValueError):
        raise SceneFormatError(path, "expected min and max of 3 numbers", f"attributes.{name}") from None
    if lo.shape != (3,) or hi.shape != (3,) or not (np.isfinite(lo).all() and np.isfinite(hi).all()):
        raise SceneFormatError(path, "expected min and max of 3 finite numbers", f"attributes.{name}")
    return lo, hi


def _sh_rotation(rot: np.ndarray, degree: int) -> np.ndarray:
    """(K, K) block-diagonal matrix turning SH coefficients by ``rot`` (fitted on directions)."""
    i = np.arange(64) + 0.5
    z = 1.0 - 2.0 * i / 64
    phi = np.pi * (1.0 + 5.0 ** 0.5) * i
    r = np.sqrt(1.0 - z * z)
    dirs = np.stack([r * np.cos(phi), r * np.sin(phi), z], 1)
    before, after = sh_basis(dirs, degree), sh_basis(dirs @ rot, degree)
    out = np.zeros((before.shape[1],) * 2)
    out[0, 0] = 1.0
    for band in range(1, degree + 1):
        s = slice(band * band, (band + 1) * (band + 1))
        out[s, s] = np.linalg.lstsq(before[:, s], after[:, s], rcond=None)[0]
    return out


def decode(path, data: bytes, sh: bytes | None, scale_range, sh_range, stride: int = 32) -> Scene:
    """The splats of ``data`` (records ``stride`` bytes apart; ``Environment.bin`` holds its SH
    inside, at byte 32) and ``sh`` (64-byte SH records, or None), in PLY axes."""
    n = len(data) // stride
    rec = np.ndarray((n,), RECORD, data, 0, (stride,))
    pos = rec["pos"].astype(np.float64)
    rgba = rec["rgba"].astype(np.float64) / 255.0
    lo, hi = scale_range
    scales = lo + (hi - lo) * (rec["scale"] / 65535.0)
    with np.errstate(divide="ignore"):
        log_scales = np.log(np.maximum(scales, np.finfo(np.float32).tiny))
    enc = rec["rot"].astype(np.int64)
    q = np.stack([(enc >> s) & 1023 for s in (0, 10, 20)], 1) / 1023.0 * math.sqrt(2) - math.sqrt(0.5)
    q = np.concatenate([q, np.sqrt(1.0 - np.minimum(1.0, (q * q).sum(1)))[:, None]], 1)
    p = q[np.arange(n)[:, None], _QLUT[enc >> 30]]  # (x, y, z, w)
    quats = p[:, [3, 0, 1, 2]]
    dc = (rgba[:, :3] - 0.5) / SH_C0
    coeffs = [dc[:, None, :]]
    if sh is not None:
        at, step = (32, stride) if stride > 32 else (0, SH_BYTES)  # inside the records, or apart
        words = np.ndarray((n, 16), "<u4", sh, at, (step, 4))[:, :15]
        words = words.astype(np.int64)
        a, b = sh_range
        chans = [(words & 2047) / 2047.0, ((words >> 11) & 1023) / 1023.0, ((words >> 21) & 2047) / 2047.0]
        coeffs.append(np.stack([a[c] + (b[c] - a[c]) * chans[c] for c in range(3)], -1))
    shs = np.concatenate(coeffs, 1)
    # LCC axes -> PLY axes
    pos = pos @ TO_PLY.T
    quats = quat_multiply(np.broadcast_to(rotmat_to_quat(TO_PLY[None])[0], quats.shape), quats)
    if shs.shape[1] > 1:
        shs = np.einsum("kj,njc->nkc", _sh_rotation(TO_PLY, 3), shs)
    return Scene(pos.astype(np.float32), quats.astype(np.float32), log_scales.astype(np.float32),
                 _binary.logit(rgba[:, 3]), shs.astype(np.float32))


@dataclass(frozen=True)
class Lcc:
    """An LCC scene's structure: levels, units (chunks, with their boxes in PLY axes)."""

    path: Path
    levels: int
    counts: tuple
    chunks: tuple
    has_sh: bool
    ranges: dict
    #: A framing box the file records (as a Streamed SOG ``splatgl lod`` wrote does): never.
    box = None

    def _read(self, name: str, offset: int, size: int) -> bytes:
        path = _file(self.path, name)
        if path is None:
            raise SceneFormatError(self.path, f"no {name} beside it")
        try:
            with open(path, "rb") as fh:
                fh.seek(offset)
                blob = fh.read(size)
        except (OSError, ValueError, OverflowError) as exc:
            raise SceneFormatError(path, f"cannot read: {getattr(exc, 'strerror', None) or exc}") from None
        if len(blob) != size:
            raise SceneFormatError(path, f"bytes {offset}-{offset + size} are past its end "
                                         f"(Index.bin names them)")
        return blob

    @property
    def has_environment(self) -> bool:
        env = _file(self.path, "Environment.bin")
        return env is not None and env.stat().st_size > 0

    def load(self, level: int = 0, chunks=None, drop_invalid: bool = False,
             environment: bool = True) -> Scene:
        """The splats of ``level`` in the units ``chunks`` (default all), then the environment."""
        if not 0 <= level < self.levels:
            raise SceneFormatError(self.path, f"level {level} does not exist (levels 0-"
                                              f"{self.levels - 1})", "totalLevel")
        parts = []
        for index in (range(len(self.chunks)) if chunks is None else chunks):
            ref = self.chunks[index].lods.get(level)
            if ref is None or ref[2] == 0:
                continue
            _, row, count = ref
            data = self._read("Data.bin", 32 * row, 32 * count)
            sh = self._read("Shcoef.bin", SH_BYTES * row, SH_BYTES * count) if self.has_sh else None
            parts.append(decode(self.path, data, sh, self.ranges["scale"], self.ranges["shcoef"]))
        env = _file(self.path, "Environment.bin")
        if environment and env is not None and env.stat().st_size:
            stride = 32 + SH_BYTES if self.has_sh else 32
            blob = _binary.read_bytes(env)
            if len(blob) % stride:
                raise SceneFormatError(env, f"{len(blob)} bytes is not a whole number of "
                                            f"{stride}-byte records")
            parts.append(decode(env, blob, blob if self.has_sh else None, self.ranges["envscale"],
                                self.ranges["envshcoef"], stride))
        if not parts:
            raise SceneFormatError(self.path, f"level {level} holds no splats", "splats")
        scene = concatenate(parts)
        return activate(self.path, scene.means, scene.quats, scene.log_scales,
                        scene.opacity_logits, scene.sh, drop_invalid=drop_invalid)


def read_structure(path: str | Path) -> Lcc:
    """``meta.lcc`` and ``Index.bin`` at ``path``, checked; no splat is read."""
    path = Path(path)
    meta = _binary.json_object(path, "meta.lcc")
    levels = meta.get("totalLevel")
    if not isinstance(levels, int) or isinstance(levels, bool) or not 1 <= levels <= 64:
        raise SceneFormatError(path, f"{levels!r} is not a level count (1-64)", "totalLevel")
    attrs = meta.get("attributes")
    if not isinstance(attrs, list) or not all(isinstance(a, dict) for a in attrs):
        raise SceneFormatError(path, "expected a list of objects", "attributes")
    attrs = {a["name"]: a for a in attrs if isinstance(a.get("name"), str)}
    file_type = meta.get("fileType")
    has_sh = file_type == "Quality" or (file_type != "Portable" and "shcoef" in attrs)
    ranges = {"scale": _range(path, attrs, "scale"), "envscale": _range(path, attrs, "envscale", "scale")}
    if has_sh:
        ranges["shcoef"] = _range(path, attrs, "shcoef")
        ranges["envshcoef"] = _range(path, attrs, "envshcoef", "shcoef")
    else:
        ranges["shcoef"] = ranges["envshcoef"] = None
    index_path = _file(path, "Index.bin")
    if index_path is None:
        raise SceneFormatError(path, "no Index.bin beside it")
    blob = _binary.read_bytes(index_path)
    size = 4 + 16 * levels
    if meta.get("indexDataSize", size) != size or len(blob) % size:
        raise SceneFormatError(index_path, f"{len(blob)} bytes is not a whole number of "
                                           f"{size}-byte units for {levels} levels", "indexDataSize")
    units = np.frombuffer(blob, np.dtype([("x", "<i2"), ("y", "<i2"), ("lods", [
        ("count", "<u4"), ("offset", "<u8"), ("size", "<u4")], levels)]))
    lods = units["lods"]
    bad = (lods["offset"] % 32 != 0) | (lods["size"].astype(np.int64) != 32 * lods["count"].astype(np.int64))
    if bad.any():
        u = int(np.flatnonzero(bad.any(1))[0])
        raise SceneFormatError(index_path, f"unit {u}: a level's offset or size is not whole "
                                           "32-byte records of its splat count")
    ends = lods["offset"].astype(np.float64) + lods["size"]
    for name, scale in (("Data.bin", 1), ("Shcoef.bin", 2))[: 1 + has_sh]:
        found = _file(path, name)
        if found is None:
            raise SceneFormatError(path, f"no {name} beside it")
        size = found.stat().st_size
        if ends.size and scale * ends.max() > size:
            u = int(np.flatnonzero((scale * ends > size).any(1))[0])
            raise SceneFormatError(index_path, f"unit {u} names bytes past the end of {name} "
                                               f"({size} bytes)")
    try:
        box = meta["boundingBox"]
        lo, hi = np.asarray(box["min"], np.float64), np.asarray(box["max"], np.float64)
        cell = np.array([float(meta["cellLengthX"]), float(meta["cellLengthY"])])
    except (TypeError, KeyError, ValueError):
        raise SceneFormatError(path, "expected boundingBox {min, max} and cellLengthX/Y "
                                     "numbers", "boundingBox") from None
    if lo.shape != (3,) or hi.shape != (3,):
        raise SceneFormatError(path, "expected min and max of 3 numbers", "boundingBox")
    chunks = []
    for unit in units:
        c_lo = np.array([lo[0] + unit["x"] * cell[0], lo[1] + unit["y"] * cell[1], lo[2]])
        c_hi = np.array([c_lo[0] + cell[0], c_lo[1] + cell[1], hi[2]])
        corners = np.array([[a, b, c] for a in (c_lo[0], c_hi[0]) for b in (c_lo[1], c_hi[1])
                            for c in (c_lo[2], c_hi[2])]) @ TO_PLY.T
        chunks.append(Chunk(corners.min(0), corners.max(0), {
            level: (0, int(unit["lods"]["offset"][level]) // 32, int(unit["lods"]["count"][level]))
            for level in range(levels)}))
    counts = tuple(int(lods["count"][:, level].sum()) for level in range(levels))
    splats = meta.get("splats")
    if splats is not None and splats != list(counts):
        raise SceneFormatError(path, f"splats {splats!r} disagree with Index.bin's {list(counts)}",
                               "splats")
    return Lcc(path, levels, counts, tuple(chunks), has_sh, ranges)


def read(path: Path, drop_invalid: bool = False, level: int = 0) -> Scene:
    """The splats of ``level`` (default 0, the finest) and the environment of the LCC scene."""
    return read_structure(path).load(level, drop_invalid=drop_invalid)


def level_info(path: Path) -> dict:
    """What ``splatgl info`` says of the levels: splats per level, units, the level loaded."""
    lod = read_structure(path)
    return {"counts": list(lod.counts), "chunks": len(lod.chunks), "loaded": 0}
