"""GaussianSplats3D ``.ksplat`` files (compression levels 0, 1 and 2).

Layout, little endian::

    main header, 4096 bytes: u8 versionMajor (0), u8 versionMinor (>= 1), u16 pad,
        u32 maxSectionCount, u32 sectionCount, u32 maxSplatCount, u32 splatCount,
        u16 compressionLevel, u16 pad, f32 sceneCenter[3], f32 minSH, f32 maxSH, zeros
    maxSectionCount section headers, 1024 bytes each: u32 splatCount, u32 maxSplatCount,
        u32 bucketSize, u32 bucketCount, f32 bucketBlockSize, u16 bucketStorageSizeBytes,
        u16 pad, u32 compressionScaleRange, u32 storage size, u32 fullBucketCount,
        u32 partiallyFilledBucketCount, u16 shDegree, zeros
    per section: u32 lengths of the partially filled buckets, bucketCount bucket centres
        (bucketStorageSizeBytes each, f32 x y z), then maxSplatCount splat records.

Splat record (``S = 3 ((shDegree + 1)^2 - 1)`` SH values, coefficient-major, RGB interleaved):

=======  ===========================  =========================================================
level    centre / scale / rotation    colour, SH
=======  ===========================  =========================================================
0        f32 x3 / f32 x3 / f32 x4     u8 RGBA, f32 x S
1        u16 x3 / f16 x3 / f16 x4     u8 RGBA, f16 x S
2        u16 x3 / f16 x3 / f16 x4     u8 RGBA, u8 x S: ``minSH + (maxSH - minSH) b / 255``
=======  ===========================  =========================================================

Scales are linear, rotations (w, x, y, z), RGB ``255 (0.5 + SH_C0 f_dc)``, A ``255 opacity``.
Levels 1-2 store centres relative to their bucket: ``(u - range) (blockSize / 2) / range +
bucketCentre``.  Splat ``i`` of a section is in bucket ``i // bucketSize`` among the full
buckets, then in the partially filled ones by their listed lengths.

The header's ``sectionCount`` and ``maxSplatCount`` can be 0 in files that are otherwise fine
(fixture ``minimal.ksplat``): sections are read up to ``maxSectionCount`` (or 1 when that is 0
and the file holds more than the main header), and each section's own counts are trusted.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..constants import SH_C0
from ..errors import SceneFormatError
from ..scene.splats import Scene, SplatKind, activate
from . import _binary
from ._memory import check_memory
from ._messages import reader_guard

NAME = "ksplat"
EXTENSIONS = (".ksplat",)
HEADER_BYTES = 4096
SECTION_HEADER_BYTES = 1024
#: Used when the header's SH range is 0 (GaussianSplats3D's 8-bit SH range is 3, centred on 0).
DEFAULT_SH_RANGE = (-1.5, 1.5)
#: Default compressionScaleRange by level, used when the section header holds 0.
DEFAULT_SCALE_RANGE = {0: 1, 1: 32767, 2: 32767}
#: Per level: dtypes of (centre, scale, rotation, SH value).
_LEVELS = {
    0: ("<f4", "<f4", "<f4", "<f4"),
    1: ("<u2", "<f2", "<f2", "<f2"),
    2: ("<u2", "<f2", "<f2", "u1"),
}


@dataclass(frozen=True)
class Section:
    """One section header (counts as stored)."""

    splat_count: int
    max_splat_count: int
    bucket_size: int
    bucket_count: int
    bucket_block_size: float
    bucket_storage_bytes: int
    scale_range: int
    full_buckets: int
    partial_buckets: int
    sh_degree: int


def sniff(head: bytes) -> bool:
    """True for a 4096-byte main header: version 0.x (x >= 1), level <= 2, zero padding."""
    if len(head) < HEADER_BYTES or head[0] != 0 or head[1] < 1:
        return False
    level = int.from_bytes(head[20:22], "little")
    return level in _LEVELS and not any(head[64:HEADER_BYTES])


def record_dtype(level: int, sh_degree: int) -> np.dtype:
    """The packed record dtype of one splat at ``level`` with ``sh_degree``."""
    centre, scale, rot, sh = _LEVELS[level]
    fields = [("centre", centre, 3), ("scale", scale, 3), ("rotation", rot, 4), ("rgba", "u1", 4)]
    n_sh = 3 * ((sh_degree + 1) ** 2 - 1)
    if n_sh:
        fields.append(("sh", sh, n_sh))
    return np.dtype(fields)


def _section(path, data: bytes, index: int) -> Section:
    base = HEADER_BYTES + index * SECTION_HEADER_BYTES
    (count, max_count, bucket_size, bucket_count, block, storage, _pad, scale_range, _size,
     full, partial, degree) = _binary.unpack(path, "<4If2H4IH", data, base,
                                             f"section header {index}")
    if degree > 3:
        raise SceneFormatError(path, f"section {index}: SH degree {degree} (expected 0-3)",
                               "shDegree")
    if full + partial > bucket_count:
        raise SceneFormatError(path, f"section {index}: {full} full + {partial} partial buckets "
                                     f"exceed bucketCount {bucket_count}", "buckets")
    return Section(count, max(count, max_count), bucket_size, bucket_count, block, storage,
                   scale_range, full, partial, degree)


def _bucket_of(path, sec: Section, lengths: np.ndarray, index: int) -> np.ndarray:
    """(splat_count,) bucket index of each splat of a section."""
    i = np.arange(sec.splat_count, dtype=np.int64)
    in_full = sec.full_buckets * sec.bucket_size
    bucket = np.empty_like(i)
    full = i < in_full
    bucket[full] = i[full] // max(sec.bucket_size, 1)
    ends = in_full + np.cumsum(lengths.astype(np.int64))
    rest = ~full
    bucket[rest] = sec.full_buckets + np.searchsorted(ends, i[rest], side="right")
    if rest.any() and (ends.size == 0 or i[-1] >= ends[-1]):
        raise SceneFormatError(path, f"section {index}: {sec.splat_count} splats but its buckets "
                                     f"hold only {int(ends[-1]) if ends.size else in_full}",
                               "buckets")
    return bucket


def _read_section(path, data: bytes, offset: int, sec: Section, level: int, index: int,
                  sh_range: tuple[float, float]) -> tuple[tuple[np.ndarray, ...], int]:
    """Raw arrays of one section and the offset just past its data."""
    lengths = _binary.array(path, data, offset, "<u4", sec.partial_buckets,
                            f"section {index} bucket lengths", "buckets")
    offset += lengths.nbytes
    if level > 0 and sec.bucket_storage_bytes < 12 and sec.bucket_count:
        raise SceneFormatError(path, f"section {index}: bucket storage {sec.bucket_storage_bytes}"
                                     " bytes, expected at least 12", "buckets")
    _binary.need(path, data, offset, sec.bucket_count * sec.bucket_storage_bytes,
                 f"section {index} buckets", "buckets")
    bucket_base = offset
    offset += sec.bucket_count * sec.bucket_storage_bytes
    dtype = record_dtype(level, sec.sh_degree)
    _binary.check_fits(path, sec.max_splat_count, dtype.itemsize, len(data) - offset,
                       f"section {index} splats", "splats")
    rec = np.frombuffer(data, dtype, sec.splat_count, offset)
    offset += sec.max_splat_count * dtype.itemsize

    centre = rec["centre"].astype(np.float64)
    if level > 0:
        stride = sec.bucket_storage_bytes // 4
        floats = np.frombuffer(data, "<f4", sec.bucket_count * stride, bucket_base)
        centres = floats.reshape(-1, stride)[:, :3].astype(np.float64)
        scale_range = sec.scale_range or DEFAULT_SCALE_RANGE[level]
        bucket = _bucket_of(path, sec, lengths, index)
        centre = (centre - scale_range) * (sec.bucket_block_size / 2.0 / scale_range)
        centre = centre + centres[bucket]
    rgba = rec["rgba"] / 255.0
    k = (sec.sh_degree + 1) ** 2
    sh = np.empty((sec.splat_count, k, 3), np.float32)
    sh[:, 0] = (rgba[:, :3] - 0.5) / SH_C0
    if k > 1:
        rest = rec["sh"].astype(np.float64)
        if level == 2:
            rest = sh_range[0] + (sh_range[1] - sh_range[0]) * rest / 255.0
        sh[:, 1:] = rest.reshape(-1, k - 1, 3)
    raw = (centre, rec["rotation"].astype(np.float32), _binary.log_of(rec["scale"]),
           _binary.logit(rgba[:, 3]), sh)
    return raw, offset


def decode(path, data: bytes) -> tuple[np.ndarray, ...]:
    """Raw scene arrays ``(means (N, 3), quats (N, 4) w-first, log_scales (N, 3),
    opacity_logits (N,), sh (N, K, 3))`` of all sections, in file order."""
    (major, minor, max_sections, sections, _max_splats, _splats, level, _pad, *_centre,
     sh_min, sh_max) = _binary.unpack(path, "<2B2x4I2H5f", data, 0, "ksplat header")
    if major != 0 or minor < 1:
        raise SceneFormatError(path, f"ksplat version {major}.{minor} is not supported "
                                     "(supported: 0.1 and later 0.x)", "version")
    if level not in _LEVELS:
        raise SceneFormatError(path, f"compression level {level} is not supported "
                                     f"(supported: {sorted(_LEVELS)})", "compressionLevel")
    count = max_sections or sections or (1 if len(data) > HEADER_BYTES else 0)
    _binary.check_fits(path, count, SECTION_HEADER_BYTES, len(data) - HEADER_BYTES,
                       f"{count} section headers", "maxSectionCount")
    sh_range = (sh_min, sh_max) if sh_min != sh_max else DEFAULT_SH_RANGE
    offset = HEADER_BYTES + count * SECTION_HEADER_BYTES
    sections = [_section(path, data, index) for index in range(count)]
    total = sum(sec.splat_count for sec in sections)
    degree = max((sec.sh_degree for sec in sections), default=0)
    # temporaries per splat: float64 centres, colours and SH, float32 copies (as SPZ)
    check_memory(path, total, (degree + 1) ** 2, 160 + 16 * 3 * ((degree + 1) ** 2 - 1),
                 len(data), "splatCount")
    parts = []
    for index, sec in enumerate(sections):
        raw, offset = _read_section(path, data, offset, sec, level, index, sh_range)
        if sec.splat_count:
            parts.append(raw)
    if not parts:
        raise SceneFormatError(path, "the scene has no splats (every section is empty)")
    degrees = {p[4].shape[1] for p in parts}
    if len(degrees) > 1:
        raise SceneFormatError(path, "sections have different SH degrees", "shDegree")
    return tuple(np.concatenate([p[j] for p in parts]) for j in range(5))


@reader_guard
def read(path: Path, drop_invalid: bool = False) -> Scene:
    """Load a ksplat file as a 3DGS :class:`Scene` (values through :func:`activate`)."""
    means, quats, log_scales, logits, sh = decode(path, _binary.read_bytes(path))
    return activate(path, means, quats, log_scales, logits, sh, SplatKind.GAUSSIAN_3D,
                    drop_invalid)
