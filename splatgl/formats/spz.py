"""Niantic SPZ (``*.spz``): versions 1-3 (gzip or raw body) and the version 4 container.

Header, 16 bytes little endian: ``uint32 magic 0x5053474e ('NGSP')``, ``uint32 version``,
``uint32 numPoints``, ``uint8 shDegree`` (0-3), ``uint8 fractionalBits`` (0-23),
``uint8 flags`` (bit 0: trained with antialiasing, not represented in :class:`Scene`; bit 1:
extension records follow, refused), ``uint8 reserved`` (0; version 4: number of streams).

Versions 1-3: the header and the attribute arrays, one after another, gzip-compressed (a raw,
un-gzipped body is accepted too); the body must hold exactly ``numPoints`` points and the gzip
trailer (CRC-32, length) must match.  Version 4 (not gzip): a 32-byte header, ``uint32
tocByteOffset`` (32) at byte 16 and 12 reserved bytes, then at ``tocByteOffset`` one
``(uint64 compressedSize, uint64 uncompressedSize)`` per stream, then the streams back to back
up to the end of the file, each one zstd frame holding one attribute array laid out as in
version 3.  Layout determined from the two version 4 files in
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
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import zstandard

from ..errors import SceneFormatError
from ..scene import Scene, SplatKind, activate
from . import _binary
from ._memory import check_memory
from ._messages import quote, reader_guard

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


#: Highest fractionalBits: positions are 24-bit signed fixed point, so with more than 23
#: fractional bits no position could reach 1 (writers use 12; the minimal fixtures 8).
MAX_FRACTIONAL_BITS = 23
#: Flag bits: 0x1 trained with antialiasing; 0x2 extension records follow the header
#: (Niantic's reader); splatgl reads no extensions, and they can change how SH decode.
FLAG_ANTIALIASED = 0x1
FLAG_EXTENSIONS = 0x2
#: Version 4: the header is 32 bytes; ``uint32 tocByteOffset`` at byte 16, 12 reserved bytes.
V4_HEADER_BYTES = 32
#: Deflate never expands more than this (a 258-byte match per ~2 bits): a gzip body claiming
#: more bytes than this times its compressed size is truncated or has a wrong numPoints.
DEFLATE_MAX_RATIO = 1032
#: Decoding temporaries per splat beyond the scene arrays (float64 positions, colours, scales
#: and quaternions; measured about 112 bytes on donut_sh0_v2.spz), and per SH value.
WORK_BYTES_PER_SPLAT = 128
WORK_BYTES_PER_SH_VALUE = 12


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

    def point_bytes(self) -> int:
        """Bytes per point over all attribute arrays."""
        return sum(b for _, b in self.attribute_bytes())


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
    """The header at the start of ``data`` (decompressed), every field bounded.

    version 1-4; shDegree 0-3; fractionalBits 0-:data:`MAX_FRACTIONAL_BITS` (unused by
    version 1's float16 positions); flags only bit 0 (bit 1, extensions, is refused: they can
    change the decoding); the reserved byte 0 in versions 1-3 and, in version 4, the stream
    count, exactly one stream per attribute array.
    """
    magic, *fields = _binary.unpack(path, HEADER_FORMAT, data, 0, "SPZ header")
    if magic != MAGIC:
        raise SceneFormatError(path, f"bad magic {quote(magic)}, expected 'NGSP'", "magic")
    header = Header(*fields)
    if header.version not in SUPPORTED_VERSIONS:
        raise SceneFormatError(path, f"SPZ version {header.version} is not supported "
                                     f"(supported: {', '.join(map(str, SUPPORTED_VERSIONS))})",
                               "version")
    if header.sh_degree > 3:
        raise SceneFormatError(path, f"SH degree {header.sh_degree} (expected 0-3)", "shDegree")
    if header.version > 1 and header.fractional_bits > MAX_FRACTIONAL_BITS:
        raise SceneFormatError(path, f"{header.fractional_bits} is outside 0-"
                                     f"{MAX_FRACTIONAL_BITS} (positions are 24-bit signed fixed "
                                     "point; writers use 12)", "fractionalBits")
    if header.flags & FLAG_EXTENSIONS:
        raise SceneFormatError(path, f"flags 0x{header.flags:02x}: bit 1 (extension records) is "
                                     "set; SPZ extensions are not supported", "flags")
    if header.flags & ~FLAG_ANTIALIASED:
        raise SceneFormatError(path, f"flags 0x{header.flags:02x}: unknown bits "
                                     f"0x{header.flags & ~FLAG_ANTIALIASED:02x} set (only bit 0, "
                                     "antialiased, is defined)", "flags")
    streams = len(header.attribute_bytes())
    if header.version == 4 and header.reserved != streams:
        raise SceneFormatError(path, f"{header.reserved} streams, expected {streams} for SH "
                                     f"degree {header.sh_degree} (one per attribute array)",
                               "numStreams")
    if header.version < 4 and header.reserved != 0:
        raise SceneFormatError(path, f"reserved byte is {header.reserved}, must be 0 in "
                                     f"version {header.version}", "reserved")
    return header


def _check_memory(path, header: Header, held_bytes: int) -> None:
    n_sh = 3 * ((header.sh_degree + 1) ** 2 - 1)
    check_memory(path, header.count, (header.sh_degree + 1) ** 2,
                 WORK_BYTES_PER_SPLAT + WORK_BYTES_PER_SH_VALUE * n_sh, held_bytes, "numPoints")


def _zlib_message(exc: zlib.error) -> str:
    text = str(exc)
    if "incorrect data check" in text:
        return "corrupt gzip stream: its CRC-32 does not match the data"
    if "incorrect length check" in text:
        return "corrupt gzip stream: the length in its trailer does not match the data"
    return f"corrupt gzip stream: {text}"


def _gunzip(path, data: bytes) -> bytes:
    """Inflate a gzip SPZ: exactly the body the header declares, then the gzip trailer.

    Never inflates more than the header says plus one byte (more is an error: numPoints too
    small), and reads to the end of the stream, so zlib checks the trailer's CRC-32 and
    length.  Bytes after the stream are an error too.
    """
    inflater = zlib.decompressobj(wbits=31)
    try:
        head = inflater.decompress(data, HEADER_BYTES)
        if len(head) < HEADER_BYTES:
            raise SceneFormatError(path, f"truncated: the gzip stream ends {len(head)} bytes "
                                         f"into the {HEADER_BYTES}-byte header")
        header = parse_header(path, head)
        if header.version == 4:
            raise SceneFormatError(path, "version 4 inside a gzip stream (version 4 files are "
                                         "not gzipped; versions 1-3 are)", "version")
        want = header.point_bytes() * header.count
        if want > DEFLATE_MAX_RATIO * len(data):
            raise SceneFormatError(
                path, f"truncated, or numPoints too large: {header.count} points need a "
                f"{want}-byte body, more than a {len(data)}-byte gzip stream can hold",
                "numPoints")
        _check_memory(path, header, len(data) + want)
        body = inflater.decompress(inflater.unconsumed_tail, want) if want else b""
        if len(body) < want:
            raise SceneFormatError(
                path, f"truncated: the gzip body ends after {len(body)} bytes; numPoints "
                f"{header.count} x {header.point_bytes()} bytes needs {want}", "numPoints")
        if inflater.decompress(inflater.unconsumed_tail, 1):
            raise SceneFormatError(
                path, f"the gzip body holds more than the {want} bytes numPoints {header.count}"
                f" x {header.point_bytes()} bytes declares", "numPoints")
    except zlib.error as exc:
        raise SceneFormatError(path, _zlib_message(exc)) from None
    if not inflater.eof:
        raise SceneFormatError(path, "truncated: the gzip stream has no end (its CRC-32 and "
                                     "length trailer is cut off or missing)")
    if inflater.unused_data:
        raise SceneFormatError(path, f"{len(inflater.unused_data)} bytes after the end of the "
                                     "gzip stream")
    return head + body


def _streams(path, data: bytes, header: Header) -> list[bytes]:
    """The decompressed attribute arrays of a version 4 container, sizes checked.

    The table of contents must follow the 32-byte header, the streams must follow the table
    back to back and end at the end of the file.
    """
    expected = header.attribute_bytes()
    (toc,) = _binary.unpack(path, "<I", data, HEADER_BYTES, "version 4 table offset")
    _binary.need(path, data, 0, V4_HEADER_BYTES, "version 4 header")
    if toc != V4_HEADER_BYTES:
        raise SceneFormatError(path, f"{toc}, expected {V4_HEADER_BYTES} (the table follows the"
                                     " header when there are no extensions)", "tocByteOffset")
    table = _binary.array(path, data, toc, "<u8", 2 * header.reserved, "stream table")
    offset = toc + table.nbytes
    total = sum(int(table[i]) for i in range(0, table.size, 2))
    if offset + total != len(data):
        raise SceneFormatError(path, f"the streams' compressed sizes add up to {total} bytes, "
                                     f"but {len(data) - offset} follow the stream table")
    _check_memory(path, header, len(data) + header.point_bytes() * header.count)
    out = []
    for i, (name, per_point) in enumerate(expected):
        packed, size = int(table[2 * i]), int(table[2 * i + 1])
        if size != per_point * header.count:
            raise SceneFormatError(path, f"stream {i} ({name}) holds {size} bytes, expected "
                                         f"{header.count} x {per_point}", name)
        out.append(zstd_decompress(path, data[offset:offset + packed], size, name))
        offset += packed
    return out


def zstd_decompress(path, blob: bytes, size: int, what: str) -> bytes:
    """Decompress one zstd frame that must inflate to exactly ``size`` bytes.

    Never reads more than ``size + 1`` bytes of output (corrupted frames cannot exhaust memory).
    """
    if not blob.startswith(ZSTD_MAGIC):
        raise SceneFormatError(path, f"stream is not zstd (starts {blob[:4].hex()})", what)
    try:
        with zstandard.ZstdDecompressor().stream_reader(blob) as reader:
            out = _read_upto(reader.read, size + 1)
    except zstandard.ZstdError as exc:
        raise SceneFormatError(path, f"corrupt zstd stream: {exc}", what) from None
    if len(out) != size:
        raise SceneFormatError(path, f"zstd stream inflates to {len(out)}"
                                     f"{'+' if len(out) > size else ''} bytes, expected {size}",
                               what)
    return out


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
    gzipped = data.startswith(b"\x1f\x8b")
    if gzipped:
        data = _gunzip(path, data)  # versions 1-3 only
    header = parse_header(path, data)
    layout = header.attribute_bytes()
    if header.version == 4:
        blobs = _streams(path, data, header)
    else:
        per_point = header.point_bytes()
        body = _binary.check_fits(path, header.count, per_point, len(data) - HEADER_BYTES,
                                  f"{header.count} points", "numPoints")
        if body != len(data) - HEADER_BYTES:
            raise SceneFormatError(
                path, f"the body holds {len(data) - HEADER_BYTES} bytes, but numPoints "
                f"{header.count} x {per_point} bytes declares {body} (a wrong numPoints or "
                f"version, or not a version {header.version} body)", "numPoints")
        if not gzipped:
            _check_memory(path, header, len(data))
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


@reader_guard
def read_spz(path: Path, drop_invalid: bool = False, flip_yz: bool | None = None) -> Scene:
    """Load an SPZ file as a 3DGS :class:`Scene`; ``flip_yz`` as in :func:`decode`."""
    raw = decode(path, _binary.read_bytes(path), flip_yz)
    return activate(path, *raw, SplatKind.GAUSSIAN_3D, drop_invalid)


@reader_guard
def read(path: Path, drop_invalid: bool = False) -> Scene:
    """Load an SPZ file, converting axes by version (see the module notes)."""
    return read_spz(path, drop_invalid)
