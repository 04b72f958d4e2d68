"""Niantic SPZ (``*.spz``): versions 1-3 (gzip or raw body) and the version 4 container.

Header, 16 bytes little endian: ``uint32 magic 0x5053474e ('NGSP')``, ``uint32 version``,
``uint32 numPoints``, ``uint8 shDegree`` (0-3), ``uint8 fractionalBits``, ``uint8 flags``
(bit 0: trained with antialiasing; not represented in :class:`Scene`), ``uint8 reserved``
(version 4: number of streams).

Versions 1-3: the header and the attribute arrays, one after another, gzip-compressed (a raw,
un-gzipped body is accepted too).  Version 4 (not gzip): after the header, ``uint64 tocOffset``
(32), ``uint64`` reserved, then at ``tocOffset`` one ``(uint64 compressedSize, uint64
uncompressedSize)`` per stream, then the streams back to back, each one zstd frame holding one
attribute array laid out as in version 3.  Layout determined from the two version 4 files in
the shared scenes (sizes match ``numPoints`` times the per-point bytes below).

Attributes, per point, in order (with ``n = numPoints``, ``S = (shDegree + 1)^2 - 1``):

=========  ========  ===========================================================================
positions  9 bytes   3 x signed 24-bit fixed point, ``/ 2^fractionalBits`` (version 1: 3 float16)
alphas     1 byte    opacity ``a / 255`` (stored logit: ``log(a / (1 - a))``, clamped)
colours    3 bytes   ``f_dc = (c / 255 - 0.5) / 0.15``
scales     3 bytes   log-scale ``s / 16 - 10``
rotations  3 bytes   versions 1-2: (x, y, z) ``b / 127.5 - 1``, ``w = sqrt(1 - |xyz|^2) >= 0``
           4 bytes   versions 3-4: uint32; bits 31..30 index the largest of (x, y, z, w); the
                     other three from index 3 down to 0 take 10 bits each from the low end (9-bit
                     magnitude ``m / 511 / sqrt(2)``, then a sign bit); the largest is positive
sh         3 S bytes ``(b - 128) / 128``, coefficient-major with RGB interleaved
=========  ========  ===========================================================================

Axes: the Niantic spec says SPZ stores RUB (OpenGL) axes, while 3DGS PLY (and so
:class:`Scene`) uses RDF.  In the shared files the version decides: every version 3-4 file
matches its source only with y and z negated (``biker_v4.spz`` against ``biker.compressed.ply``,
``minimal-v3/-v4.spz`` against ``minimal.splat``), every version 2 file matches with no flip
(``donut_sh0_v2.spz`` from spz-js against ``donut_sh0.ply``, ``minimal-v2/-raw.spz``).  So by
default versions 1-2 are read as stored and versions 3-4 are converted RUB -> RDF (means,
quaternion vector part and the odd SH coefficients); :func:`read_spz` can force either.
"""

from __future__ import annotations

import math
import shutil
import struct
import subprocess
import threading
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import SceneFormatError
from ..scene import Scene, SplatKind, activate
from . import _binary

NAME = "spz"
EXTENSIONS = (".spz",)
MAGIC = b"NGSP"
HEADER_FORMAT = "<4sIIBBBB"
HEADER_BYTES = struct.calcsize(HEADER_FORMAT)
SUPPORTED_VERSIONS = (1, 2, 3, 4)
#: f_dc = (c / 255 - 0.5) / COLOR_SCALE (verified against donut_sh0.ply).
COLOR_SCALE = 0.15
#: SH sign changes when negating y and z (a 180-degree turn about x), coefficients 1..15 in the
#: 3DGS basis order (degree 1: y z x; degree 2: xy yz zz xz xx-yy; degree 3: ...).
FLIP_YZ_SH_SIGNS = np.array([-1, -1, 1, -1, 1, 1, -1, 1, -1, 1, -1, -1, 1, -1, 1], np.float32)
#: zstd frame magic (version 4 streams).
ZSTD_MAGIC = b"\x28\xb5\x2f\xfd"


@dataclass(frozen=True)
class Header:
    """The 16-byte SPZ header."""

    version: int
    count: int
    sh_degree: int
    fractional_bits: int
    flags: int
    reserved: int

    def attribute_bytes(self) -> list[tuple[str, int]]:
        """``(name, bytes per point)`` of each attribute array, in file order."""
        sizes = [("positions", 6 if self.version == 1 else 9), ("alphas", 1), ("colors", 3),
                 ("scales", 3), ("rotations", 4 if self.version >= 3 else 3)]
        n_sh = (self.sh_degree + 1) ** 2 - 1
        return sizes + ([("sh", 3 * n_sh)] if n_sh else [])


def sniff(head: bytes) -> bool:
    """True for ``NGSP`` at byte 0, or a gzip stream whose first bytes inflate to ``NGSP``."""
    if head.startswith(MAGIC):
        return True
    if not head.startswith(b"\x1f\x8b"):
        return False
    try:
        return zlib.decompressobj(wbits=31).decompress(head, 4) == MAGIC
    except zlib.error:
        return False


def parse_header(path, data: bytes) -> Header:
    """The header at the start of ``data`` (decompressed), with version and degree checked."""
    magic, *fields = _binary.unpack(path, HEADER_FORMAT, data, 0, "SPZ header")
    if magic != MAGIC:
        raise SceneFormatError(path, f"bad magic {magic!r}, expected {MAGIC!r}", "magic")
    header = Header(*fields)
    if header.version not in SUPPORTED_VERSIONS:
        raise SceneFormatError(path, f"SPZ version {header.version} is not supported "
                                     f"(supported: {', '.join(map(str, SUPPORTED_VERSIONS))})",
                               "version")
    if header.sh_degree > 3:
        raise SceneFormatError(path, f"SH degree {header.sh_degree} (expected 0-3)", "shDegree")
    return header


def _gunzip(path, data: bytes) -> bytes:
    """Inflate a gzip SPZ, never more than the header says the body needs."""
    inflater = zlib.decompressobj(wbits=31)
    try:
        head = inflater.decompress(data, HEADER_BYTES)
        header = parse_header(path, head)
        want = sum(b for _, b in header.attribute_bytes()) * header.count
        body = inflater.decompress(inflater.unconsumed_tail, max(1, want))
    except zlib.error as exc:
        raise SceneFormatError(path, f"corrupt gzip stream: {exc}") from None
    return head + body


def _streams(path, data: bytes, header: Header) -> list[bytes]:
    """The decompressed attribute arrays of a version 4 container, sizes checked."""
    expected = header.attribute_bytes()
    if header.reserved < len(expected):
        raise SceneFormatError(path, f"{header.reserved} streams, expected at least "
                                     f"{len(expected)} for SH degree {header.sh_degree}", "streams")
    (toc,) = _binary.unpack(path, "<Q", data, HEADER_BYTES, "version 4 table offset")
    table = _binary.array(path, data, toc, "<u8", 2 * header.reserved, "stream table")
    offset = toc + table.nbytes
    out = []
    for i, (name, per_point) in enumerate(expected):
        packed, size = int(table[2 * i]), int(table[2 * i + 1])
        if size != per_point * header.count:
            raise SceneFormatError(path, f"stream {i} ({name}) holds {size} bytes, expected "
                                         f"{header.count} x {per_point}", name)
        _binary.need(path, data, offset, packed, f"stream {i} ({name})", name)
        out.append(zstd_decompress(path, data[offset:offset + packed], size, name))
        offset += packed
    return out


def zstd_decompress(path, blob: bytes, size: int, what: str) -> bytes:
    """Decompress one zstd frame that must inflate to exactly ``size`` bytes.

    Uses the ``zstandard`` package when installed, else ``compression.zstd`` (Python 3.14+),
    else the ``zstd`` command-line tool; with none of them, a :class:`SceneFormatError` says so.
    Never reads more than ``size + 1`` bytes of output (corrupted frames cannot exhaust memory).
    """
    if not blob.startswith(ZSTD_MAGIC):
        raise SceneFormatError(path, f"stream is not zstd (starts {blob[:4].hex()})", what)
    try:
        out = _zstd_backend(path, blob, size + 1, what)
    except SceneFormatError:
        raise
    except Exception as exc:  # each backend has its own error class
        raise SceneFormatError(path, f"corrupt zstd stream: {exc}", what) from None
    if len(out) != size:
        raise SceneFormatError(path, f"zstd stream inflates to {len(out)}"
                                     f"{'+' if len(out) > size else ''} bytes, expected {size}",
                               what)
    return out


def _zstd_backend(path, blob: bytes, limit: int, what: str) -> bytes:
    try:
        import zstandard
    except ImportError:
        pass
    else:
        with zstandard.ZstdDecompressor().stream_reader(blob) as reader:
            return _read_upto(reader.read, limit)
    try:
        from compression import zstd  # Python 3.14+
    except ImportError:
        pass
    else:
        return zstd.ZstdDecompressor().decompress(blob, max_length=limit)
    exe = shutil.which("zstd")
    if exe is None:
        raise SceneFormatError(path, "SPZ version 4 streams are zstd-compressed and no zstd "
                                     "decoder is available: install the 'zstandard' package",
                               what)
    with subprocess.Popen([exe, "-d", "-c", "-q"], stdin=subprocess.PIPE,
                          stdout=subprocess.PIPE, stderr=subprocess.DEVNULL) as proc:
        feeder = threading.Thread(target=_feed, args=(proc.stdin, blob), daemon=True)
        feeder.start()
        out = _read_upto(proc.stdout.read, limit)
        if len(out) >= limit:  # more output than allowed: stop it
            proc.kill()
        try:
            code = proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            code = proc.wait()
        feeder.join()
    if len(out) < limit and code != 0:
        raise SceneFormatError(path, f"corrupt zstd stream (zstd exit status {code})", what)
    return out


def _feed(pipe, blob: bytes) -> None:
    try:
        pipe.write(blob)
        pipe.close()
    except OSError:  # the reader stopped early
        pass


def _read_upto(read, limit: int) -> bytes:
    parts, got = [], 0
    while got < limit:
        chunk = read(min(limit - got, 1 << 22))
        if not chunk:
            break
        parts.append(chunk)
        got += len(chunk)
    return b"".join(parts)


def _arrays(path, data: bytes) -> tuple[Header, dict[str, np.ndarray]]:
    """Header and each attribute as a uint8 (n, bytes per point) array."""
    if data.startswith(b"\x1f\x8b"):
        data = _gunzip(path, data)
    header = parse_header(path, data)
    layout = header.attribute_bytes()
    if header.version == 4:
        blobs = _streams(path, data, header)
    else:
        per_point = sum(b for _, b in layout)
        _binary.check_fits(path, header.count, per_point, len(data) - HEADER_BYTES,
                           f"{header.count} points", "numPoints")
        blobs, offset = [], HEADER_BYTES
        for _, b in layout:
            blobs.append(data[offset:offset + b * header.count])
            offset += b * header.count
    arrays = {name: np.frombuffer(blob, np.uint8).reshape(header.count, b)
              for (name, b), blob in zip(layout, blobs)}
    return header, arrays


def _positions(header: Header, raw: np.ndarray) -> np.ndarray:
    if header.version == 1:
        return raw.copy().view("<f2").astype(np.float64)
    b = raw.reshape(-1, 3, 3).astype(np.int32)
    fixed = b[..., 0] | (b[..., 1] << 8) | (b[..., 2] << 16)
    fixed = np.where(fixed & 0x800000, fixed - (1 << 24), fixed)
    return fixed * 2.0 ** -header.fractional_bits


def unpack_rotation_xyz(raw: np.ndarray) -> np.ndarray:
    """(N, 4) float64 (w, x, y, z) from (N, 3) uint8 x, y, z (versions 1-2), w >= 0."""
    xyz = raw / 127.5 - 1.0
    w = np.sqrt(np.maximum(0.0, 1.0 - (xyz * xyz).sum(axis=1)))
    return np.concatenate([w[:, None], xyz], axis=1)


def unpack_rotation_smallest3(raw: np.ndarray) -> np.ndarray:
    """(N, 4) float64 (w, x, y, z) from (N, 4) uint8 smallest-three words (versions 3-4)."""
    b = raw.astype(np.uint32)
    word = b[:, 0] | (b[:, 1] << 8) | (b[:, 2] << 16) | (b[:, 3] << 24)
    largest = (word >> 30).astype(np.intp)
    xyzw = np.zeros((raw.shape[0], 4))
    for i in range(3, -1, -1):
        mine = largest != i
        value = (word & 511) / 511.0 * math.sqrt(0.5)
        value = np.where((word >> 9) & 1, -value, value)
        xyzw[:, i] = np.where(mine, value, 0.0)
        word = np.where(mine, word >> 10, word)
    rows = np.arange(raw.shape[0])
    xyzw[rows, largest] = np.sqrt(np.maximum(0.0, 1.0 - (xyzw * xyzw).sum(axis=1)))
    return xyzw[:, [3, 0, 1, 2]]


def flips_by_default(version: int) -> bool:
    """Whether a file of this SPZ ``version`` is converted RUB -> RDF (see the module notes)."""
    return version >= 3


def decode(path, data: bytes, flip_yz: bool | None = None) -> tuple[np.ndarray, ...]:
    """Raw scene arrays ``(means (N, 3), quats (N, 4) w-first, log_scales (N, 3),
    opacity_logits (N,), sh (N, K, 3))`` of an SPZ file's bytes.

    ``flip_yz`` converts RUB to RDF axes (negates y and z of the means, of the quaternion's
    vector part and the matching SH coefficients); None decides by version
    (:func:`flips_by_default`).
    """
    header, a = _arrays(path, data)
    if flip_yz is None:
        flip_yz = flips_by_default(header.version)
    means = _positions(header, a["positions"])
    logits = _binary.logit(a["alphas"][:, 0] / 255.0)
    dc = (a["colors"] / 255.0 - 0.5) / COLOR_SCALE
    log_scales = (a["scales"] / 16.0 - 10.0).astype(np.float32)
    if header.version >= 3:
        quats = unpack_rotation_smallest3(a["rotations"])
    else:
        quats = unpack_rotation_xyz(a["rotations"])
    k = (header.sh_degree + 1) ** 2
    sh = np.empty((header.count, k, 3), np.float32)
    sh[:, 0] = dc
    if k > 1:
        sh[:, 1:] = ((a["sh"].astype(np.float32) - 128.0) / 128.0).reshape(-1, k - 1, 3)
    if flip_yz:
        means[:, 1:] *= -1.0
        quats[:, 2:] *= -1.0
        sh[:, 1:] *= FLIP_YZ_SH_SIGNS[: k - 1, None]
    return means, quats, log_scales, logits, sh


def read_spz(path: Path, drop_invalid: bool = False, flip_yz: bool | None = None) -> Scene:
    """Load an SPZ file as a 3DGS :class:`Scene`; ``flip_yz`` as in :func:`decode`."""
    raw = decode(path, _binary.read_bytes(path), flip_yz)
    return activate(path, *raw, SplatKind.GAUSSIAN_3D, drop_invalid)


def read(path: Path, drop_invalid: bool = False) -> Scene:
    """Load an SPZ file, converting axes by version (see the module notes)."""
    return read_spz(path, drop_invalid)
