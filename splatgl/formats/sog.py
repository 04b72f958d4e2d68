"""PlayCanvas SOG (``*.sog`` zip bundle, or a folder with ``meta.json``): reader (v1, v2).

A SOG scene is a ``meta.json`` plus lossless WebP textures (RGBA, ``W x H >= count`` texels, one
texel per splat in row-major order); a ``.sog`` file is the same files in one zip.  Version 2:

- ``means``: ``means_l.webp`` / ``means_u.webp`` hold the low / high byte of 16-bit ``u`` per axis
  (RGB); ``v = mins + (maxs - mins) u / 65535`` is ``sign(x) log(1 + |x|)``, so
  ``x = sign(v) (exp(|v|) - 1)``.
- ``scales``: ``scales.webp`` RGB are indices into ``codebook`` (256 log-scales).
- ``quats``: ``quats.webp`` RGB are the smallest three of (w, x, y, z), ``(b / 255 * 2 - 1) /
  sqrt(2)`` each, in index order; A is ``252 +`` the index of the largest (recomputed, >= 0).
- ``sh0``: ``sh0.webp`` RGB index ``codebook`` (256 f_dc values), A is ``255 * opacity``.
- ``shN`` (SH degrees 1-3, optional): ``shN_labels.webp`` (R + 256 G) picks a palette entry;
  ``shN_centroids.webp`` is ``64 * coeffs`` texels wide, entry ``l`` at row ``l // 64``, texels
  ``(l % 64) coeffs + j`` for coefficient ``j``, RGB indexing ``codebook`` (256 values).

Version 1 (no ``version`` key; ``means.shape``) stores linear min/max ranges instead of codebooks:
``scales`` / ``sh0`` (f_dc and the opacity logit in A) / ``shN`` bytes map to ``min + (max -
min) b / 255``.  Both versions store the PLY axes (the scene's own).

The writer (version 2) is :mod:`splatgl.formats.sog_write`.
"""

from __future__ import annotations

import json
import math
import zipfile
from pathlib import Path

import numpy as np

from ..constants import sh_coeff_count
from ..errors import SceneFormatError
from ..scene.json_text import unique_keys
from ..scene.splats import Scene, SplatKind, activate
from . import _binary, webp
from ._messages import quote
from . import quantise as qz

NAME = "sog"
EXTENSIONS = (".sog", "meta.json")
#: The largest zip entry or meta.json read (a corrupted size field cannot exhaust memory).
MAX_ENTRY_BYTES = 1 << 30
_ZIP_MAGIC = b"PK\x03\x04"


def sniff(head: bytes) -> bool:
    """A zip whose first entry is a WebP texture or meta.json, or JSON with a ``means`` key."""
    if head.startswith(_ZIP_MAGIC):
        return b".webp" in head[30:300] or b"meta.json" in head[30:300]
    return head.lstrip().startswith(b"{") and b'"means"' in head


class _Files:
    """The files of a SOG scene, from a zip bundle or from meta.json's folder."""

    def __init__(self, path: Path):
        self.path = path
        self.zip = None
        try:
            with open(path, "rb") as fh:
                head = fh.read(32)
        except OSError as exc:
            raise SceneFormatError(path, f"cannot read: {exc.strerror or exc}") from None
        magic = head[:4]
        if magic != _ZIP_MAGIC and path.name.lower().endswith(".sog"):
            # a .sog is a zip; read as meta.json text, a stray text file was 'meta.json is
            # not valid JSON', which named a file the user never gave
            raise SceneFormatError(path, "not a SOG bundle: a .sog file is a zip archive "
                                         "(starting 'PK\\x03\\x04'), this one "
                                         + (f"starts {quote(head)}" if head else "is empty"))
        if magic == _ZIP_MAGIC:
            try:
                self.zip = zipfile.ZipFile(path)
            except (zipfile.BadZipFile, OSError, ValueError) as exc:
                raise SceneFormatError(path, f"corrupt zip bundle: {exc}") from None

    def get(self, name: str) -> bytes:
        if not isinstance(name, str) or not name or "/" in name or "\\" in name or name in (".", ".."):
            raise SceneFormatError(self.path, f"file name {name!r} is not a plain file name",
                                   "files")
        if self.zip is None:
            return _binary.read_bytes(self.path.parent / name)
        try:
            info = self.zip.getinfo(name)
        except KeyError:
            raise SceneFormatError(self.path, f"the bundle has no '{name}'", "files") from None
        if info.file_size > MAX_ENTRY_BYTES:
            raise SceneFormatError(self.path, f"'{name}' claims {info.file_size} bytes", "files")
        try:
            return self.zip.read(info)
        except Exception as exc:  # zlib.error, BadZipFile, EOFError, NotImplementedError ...
            raise SceneFormatError(self.path, f"cannot unpack '{name}': {exc}", "files") from None

    def meta(self) -> dict:
        blob = self.get("meta.json") if self.zip is not None else _binary.read_bytes(self.path)
        try:
            meta = json.loads(blob.decode("utf-8"), object_pairs_hook=unique_keys)
        except (UnicodeDecodeError, ValueError, RecursionError) as exc:
            raise SceneFormatError(self.path, f"meta.json is not valid JSON: {exc}") from None
        if not isinstance(meta, dict):
            raise SceneFormatError(self.path, "meta.json is not a JSON object")
        return meta


def _get(path, meta: dict, key: str):
    """``meta[a][b]...`` for ``key = 'a.b'``, or an error naming the missing field."""
    obj = meta
    for part in key.split("."):
        if not isinstance(obj, dict) or part not in obj:
            raise SceneFormatError(path, "missing in meta.json", key)
        obj = obj[part]
    return obj


def _numbers(path, meta: dict, key: str, length: int | None = None) -> np.ndarray:
    """float64 array of the JSON number list (or number) at ``key``, finite, of ``length``."""
    value = _get(path, meta, key)
    try:
        arr = np.asarray(value, np.float64)
    except (TypeError, ValueError):
        raise SceneFormatError(path, "expected numbers", key) from None
    if arr.dtype != np.float64 or not np.isfinite(arr).all() or (
            length is not None and arr.shape != (length,)):
        raise SceneFormatError(path, f"expected {length or 'a list of'} finite numbers", key)
    return arr


def _count(path, value, key: str) -> int:
    if not isinstance(value, int) or isinstance(value, bool) or not 0 < value <= (1 << 28):
        raise SceneFormatError(path, f"splat count {value!r} is not a positive integer", key)
    return value


def _texture(path, files: _Files, meta: dict, key: str, index: int, count: int) -> np.ndarray:
    """(count, 4) uint8 texels of the ``index``-th file of ``meta[key]``."""
    names = _get(path, meta, f"{key}.files")
    if not isinstance(names, list) or len(names) <= index:
        raise SceneFormatError(path, f"expected at least {index + 1} file names", f"{key}.files")
    rgba = webp.decode(path, files.get(names[index]), f"{key}.files[{index}]", min_texels=count)
    return rgba.reshape(-1, 4)[:count]


def _means(path, files, meta, count) -> np.ndarray:
    lo = _texture(path, files, meta, "means", 0, count)[:, :3].astype(np.float64)
    hi = _texture(path, files, meta, "means", 1, count)[:, :3].astype(np.float64)
    mins, maxs = _numbers(path, meta, "means.mins", 3), _numbers(path, meta, "means.maxs", 3)
    span = np.where(maxs - mins != 0.0, maxs - mins, 1.0)
    v = mins + span * ((lo + 256.0 * hi) / 65535.0)
    with np.errstate(over="ignore"):
        return np.sign(v) * np.expm1(np.abs(v))


def _quats(path, files, meta, count) -> np.ndarray:
    t = _texture(path, files, meta, "quats", 0, count)
    tag = t[:, 3].astype(np.intp) - qz.SOG_QUAT_TAG
    bad = (tag < 0) | (tag > 3)
    if bad.any():
        raise SceneFormatError(path, f"{int(bad.sum())} quaternion tag(s) outside 252-255 (first "
                                     f"at splat {int(np.flatnonzero(bad)[0])})", "quats")
    abc = (t[:, :3] / 255.0 * 2.0 - 1.0) / math.sqrt(2.0)
    quats = np.empty((count, 4))
    rows = np.arange(count)
    others = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])
    quats[rows[:, None], others[tag]] = abc
    quats[rows, tag] = np.sqrt(np.maximum(0.0, 1.0 - (abc * abc).sum(axis=1)))
    return quats


def _codebook(path, meta, key) -> np.ndarray:
    book = _numbers(path, meta, key)
    if np.abs(book).max(initial=0.0) > np.finfo(np.float32).max:
        raise SceneFormatError(path, "values beyond float32's range", key)
    book = book.astype(np.float32)
    if book.ndim != 1 or not 1 <= book.size <= 256:
        raise SceneFormatError(path, f"expected 1-256 numbers, found {book.size}", key)
    return np.concatenate([book, np.full(256 - book.size, book[-1], np.float32)])


def _sh_rest_v2(path, files, meta, count) -> np.ndarray | None:
    if "shN" not in meta:
        return None
    bands = _get(path, meta, "shN.bands")
    if bands not in (1, 2, 3):
        raise SceneFormatError(path, f"SH bands {bands!r}, expected 1-3", "shN.bands")
    coeffs = sh_coeff_count(bands) - 1
    palette = _count(path, _get(path, meta, "shN.count"), "shN.count")
    book = _codebook(path, meta, "shN.codebook")
    labels_t = _texture(path, files, meta, "shN", 1, count)
    labels = labels_t[:, 0].astype(np.int64) | (labels_t[:, 1].astype(np.int64) << 8)
    names = _get(path, meta, "shN.files")
    cen = webp.decode(path, files.get(names[0]), "shN.files[0]")
    if cen.shape[1] != 64 * coeffs:
        raise SceneFormatError(path, f"centroids texture is {cen.shape[1]} texels wide, expected "
                                     f"{64 * coeffs} for {bands} SH bands", "shN.files[0]")
    limit = min(palette, 64 * cen.shape[0])
    bad = labels >= limit
    if bad.any():
        raise SceneFormatError(path, f"{int(bad.sum())} palette label(s) >= {limit} (first at "
                                     f"splat {int(np.flatnonzero(bad)[0])})", "shN")
    entries = cen.reshape(-1, 64, coeffs, 4).reshape(-1, coeffs, 4)[:, :, :3]  # (64 H, coeffs, 3)
    return book[entries[labels]]  # (count, coeffs, 3)


def _decode_v2(path, files, meta):
    count = _count(path, _get(path, meta, "count"), "count")
    means = _means(path, files, meta, count)
    quats = _quats(path, files, meta, count)
    scales = _codebook(path, meta, "scales.codebook")[
        _texture(path, files, meta, "scales", 0, count)[:, :3]]
    sh0 = _texture(path, files, meta, "sh0", 0, count)
    dc = _codebook(path, meta, "sh0.codebook")[sh0[:, :3]]
    logits = _binary.logit(sh0[:, 3] / 255.0)
    rest = _sh_rest_v2(path, files, meta, count)
    sh = dc[:, None, :] if rest is None else np.concatenate([dc[:, None, :], rest], axis=1)
    return means, quats, scales, logits, sh


def _decode_v1(path, files, meta):
    shape = _get(path, meta, "means.shape")
    if not isinstance(shape, list) or not shape:
        raise SceneFormatError(path, "expected [count, 3]", "means.shape")
    count = _count(path, shape[0], "means.shape")
    means = _means(path, files, meta, count)
    quats = _quats(path, files, meta, count)

    def lerp(key: str, channels: int) -> np.ndarray:
        lo, hi = _numbers(path, meta, f"{key}.mins", channels), _numbers(path, meta, f"{key}.maxs", channels)
        t = _texture(path, files, meta, key, 0, count)[:, :channels] / 255.0
        return lo + (hi - lo) * t

    scales = lerp("scales", 3)
    sh0 = lerp("sh0", 4)
    sh = sh0[:, None, :3]
    if "shN" in meta:
        names = _get(path, meta, "shN.files")
        cen = webp.decode(path, files.get(names[0]), "shN.files[0]")
        bands = {192: 1, 512: 2, 960: 3}.get(cen.shape[1])
        if bands is None:
            raise SceneFormatError(path, f"centroids texture is {cen.shape[1]} texels wide; "
                                         "expected 192, 512 or 960", "shN.files[0]")
        coeffs = sh_coeff_count(bands) - 1
        labels_t = _texture(path, files, meta, "shN", 1, count)
        labels = labels_t[:, 0].astype(np.int64) | (labels_t[:, 1].astype(np.int64) << 8)
        limit = 64 * cen.shape[0]
        if (labels >= limit).any():
            raise SceneFormatError(path, f"palette label(s) >= {limit}", "shN")
        lo, hi = float(_numbers(path, meta, "shN.mins")), float(_numbers(path, meta, "shN.maxs"))
        entries = cen.reshape(-1, coeffs, 4)[:, :, :3]
        rest = lo + (hi - lo) * (entries[labels] / 255.0)
        sh = np.concatenate([sh, rest], axis=1)
    return means, quats, scales, sh0[:, 3], sh


def read_meta(path: Path) -> dict:
    """The parsed meta.json of a SOG folder or bundle."""
    return _Files(Path(path)).meta()


def read(path: Path, drop_invalid: bool = False) -> Scene:
    """Load a SOG scene (``.sog`` bundle or ``meta.json``), version 1 or 2."""
    path = Path(path)
    files = _Files(path)
    meta = files.meta()
    version = meta.get("version")
    try:
        if version == 2:
            raw = _decode_v2(path, files, meta)
        elif version is None and isinstance(meta.get("means"), dict) and "shape" in meta["means"]:
            raw = _decode_v1(path, files, meta)
        else:
            raise SceneFormatError(path, f"SOG version {version!r} is not supported (supported: "
                                         "2, and version 1, which has no 'version' key and "
                                         "gives means.shape)", "version")
    except (TypeError, AttributeError, KeyError, IndexError, ValueError) as exc:
        if isinstance(exc, SceneFormatError):
            raise
        # meta.json values of the wrong shape (a string where numbers belong, ...)
        raise SceneFormatError(path, f"malformed meta.json ({type(exc).__name__}: "
                                     f"{str(exc)[:100]})") from None
    means, quats, scales, logits, sh = raw
    return activate(path, means, quats, np.asarray(scales, np.float32),
                    np.asarray(logits, np.float32), np.asarray(sh, np.float32),
                    SplatKind.GAUSSIAN_3D, drop_invalid)


def stored_bytes(path: Path) -> int:
    """Bytes a SOG scene occupies: the bundle, or meta.json plus the textures it names."""
    path = Path(path)
    size = path.stat().st_size
    if not path.name.lower().endswith(".json"):
        return size
    names = {n for v in read_meta(path).values() if isinstance(v, dict)
             for n in (v.get("files") or []) if isinstance(n, str) and "/" not in n}
    return size + sum((path.parent / n).stat().st_size for n in names
                      if (path.parent / n).is_file())
