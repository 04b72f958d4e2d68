"""Niantic SPZ (``*.spz``): versions 1-3 (gzip or raw body) and the version 4 container.

Header, 16 bytes little endian: ``uint32 magic 0x5053474e ('NGSP')``, ``uint32 version``,
``uint32 numPoints``, ``uint8 shDegree`` (0-3), ``uint8 fractionalBits`` (0-23),
``uint8 flags`` (bit 0: trained with antialiasing, not represented in :class:`Scene`; bit 1:
extension records follow), ``uint8 reserved`` (0; version 4: number of streams).

Versions 1-3: the header and the attribute arrays, one after another, gzip-compressed (a raw,
un-gzipped body is accepted too); the body must hold exactly ``numPoints`` points and the gzip
trailer (CRC-32, length) must match; extension records (flags bit 1) follow the arrays.
Version 4 (not gzip): a 32-byte header, ``uint32 tocByteOffset`` at byte 16 and 12 reserved
bytes, extension records up to ``tocByteOffset`` (32 without them), then there one
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

Axes: RDF in :class:`Scene`; which axes a file stores and the conversion are decided in
:mod:`.spz_axes` (its extension record, else ``axes``/``--spz-axes``, else RUB for versions 3-4
as the SPZ specification says and the stored axes for versions 1-2).
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import zstandard

from ..errors import SceneFormatError
from ..scene.splats import Scene, SplatKind, activate
from . import _binary, spz_attributes, spz_axes
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
#: zstd frame magic (version 4 streams).
ZSTD_MAGIC = b"\x28\xb5\x2f\xfd"


#: Highest fractionalBits: positions are 24-bit signed fixed point, so with more than 23
#: fractional bits no position could reach 1 (writers use 12; the minimal fixtures 8).
MAX_FRACTIONAL_BITS = 23
#: Flag bits: 0x1 trained with antialiasing; 0x2 extension records follow (see :mod:`.spz_axes`).
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
    version 1's float16 positions); flags bits 0-1; the reserved byte 0 in versions 1-3 and,
    in version 4, the stream count, exactly one stream per attribute array.
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
    known = FLAG_ANTIALIASED | FLAG_EXTENSIONS
    if header.flags & ~known:
        raise SceneFormatError(path, f"flags 0x{header.flags:02x}: unknown bits "
                                     f"0x{header.flags & ~known:02x} set (bit 0, antialiased, "
                                     "and bit 1, extensions, are defined)", "flags")
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
    """Inflate a gzip SPZ: exactly the body the header declares (and, with flags bit 1, at most
    :data:`~.spz_axes.MAX_EXTENSION_BYTES` of extension records), then the gzip trailer.

    Never inflates more than that plus one byte (more is an error: numPoints too small), and
    reads to the end of the stream, so zlib checks the trailer's CRC-32 and length.  Bytes
    after the stream are an error too.
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
        if header.flags & FLAG_EXTENSIONS:
            body += inflater.decompress(inflater.unconsumed_tail, spz_axes.MAX_EXTENSION_BYTES + 1)
            if len(body) > want + spz_axes.MAX_EXTENSION_BYTES:
                raise SceneFormatError(path, f"more than {spz_axes.MAX_EXTENSION_BYTES} bytes of "
                                             "extension records after the arrays", "extensions")
        elif inflater.decompress(inflater.unconsumed_tail, 1):
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


def _v4_zone(path, data: bytes, header: Header) -> tuple[int, bytes]:
    """``tocByteOffset`` of a version 4 file and its extension records' bytes (32 to there)."""
    (toc,) = _binary.unpack(path, "<I", data, HEADER_BYTES, "version 4 table offset")
    _binary.need(path, data, 0, V4_HEADER_BYTES, "version 4 header")
    if toc != V4_HEADER_BYTES and not header.flags & FLAG_EXTENSIONS:
        raise SceneFormatError(path, f"{toc}, expected {V4_HEADER_BYTES} (the table follows the"
                                     " header when flags bit 1, extensions, is clear)",
                               "tocByteOffset")
    if not V4_HEADER_BYTES <= toc <= len(data):
        raise SceneFormatError(path, f"{toc}, outside the file's {V4_HEADER_BYTES}-{len(data)}",
                               "tocByteOffset")
    return toc, data[V4_HEADER_BYTES:toc]


def _streams(path, data: bytes, header: Header, toc: int) -> list[bytes]:
    """The decompressed attribute arrays of a version 4 container, sizes checked.

    The table of contents sits at ``toc`` (after the header and extension records), the
    streams must follow the table back to back and end at the end of the file.
    """
    expected = header.attribute_bytes()
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


def _container(path, data: bytes) -> tuple[Header, bytes, bytes]:
    """Header, the (inflated) file and its extension records' bytes; sizes checked."""
    gzipped = data.startswith(b"\x1f\x8b")
    if gzipped:
        data = _gunzip(path, data)  # versions 1-3 only
    header = parse_header(path, data)
    if header.version == 4:
        _, zone = _v4_zone(path, data, header)
        return header, data, zone
    per_point = header.point_bytes()
    body = _binary.check_fits(path, header.count, per_point, len(data) - HEADER_BYTES,
                              f"{header.count} points", "numPoints")
    zone = data[HEADER_BYTES + body:]
    if len(zone) > spz_axes.MAX_EXTENSION_BYTES and header.flags & FLAG_EXTENSIONS:
        raise SceneFormatError(path, f"{len(zone)} bytes after the arrays, more than the "
                                     f"{spz_axes.MAX_EXTENSION_BYTES} extension records may take "
                                     "(a wrong numPoints?)", "numPoints")
    if zone and not header.flags & FLAG_EXTENSIONS:
        raise SceneFormatError(
            path, f"the body holds {len(data) - HEADER_BYTES} bytes, but numPoints "
            f"{header.count} x {per_point} bytes declares {body} (a wrong numPoints or "
            f"version, or not a version {header.version} body)", "numPoints")
    if not gzipped:
        _check_memory(path, header, len(data))
    return header, data, zone


def _arrays(path, data: bytes) -> tuple[Header, dict[str, np.ndarray], list]:
    """Header, each attribute as a uint8 (n, bytes per point) array, and the extension
    records ``(type, payload)``."""
    header, data, zone = _container(path, data)
    records = spz_axes.parse_records(path, zone)
    layout = header.attribute_bytes()
    if header.version == 4:
        blobs = _streams(path, data, header, V4_HEADER_BYTES + len(zone))
    else:
        blobs, offset = [], HEADER_BYTES
        for _, b in layout:
            blobs.append(data[offset:offset + b * header.count])
            offset += b * header.count
    arrays = {name: np.frombuffer(blob, np.uint8).reshape(header.count, b)
              for (name, b), blob in zip(layout, blobs)}
    return header, arrays, records


def read_axes(path, axes: str | None = None) -> spz_axes.Axes:
    """How :func:`read_spz` decides the axes of the SPZ file ``path`` (see :mod:`.spz_axes`),
    from its header and extension records (a gzip body is inflated, nothing is decoded)."""
    header, _, zone = _container(path, _binary.read_bytes(path))
    return spz_axes.resolve(path, header.version, spz_axes.parse_records(path, zone), axes)


def decode_with_axes(path, data: bytes, axes: str | None = None):
    """:func:`decode`'s arrays, and the :class:`~.spz_axes.Axes` they were converted from."""
    header, a, records = _arrays(path, data)
    stored = spz_axes.resolve(path, header.version, records, axes)
    means = spz_attributes.positions(a["positions"], header.version, header.fractional_bits)
    logits = _binary.logit(a["alphas"][:, 0] / 255.0)
    dc = (a["colors"] / 255.0 - 0.5) / COLOR_SCALE
    log_scales = (a["scales"] / 16.0 - 10.0).astype(np.float32)
    if header.version >= 3:
        quats = spz_attributes.unpack_rotation_smallest3(a["rotations"])
    else:
        quats = spz_attributes.unpack_rotation_xyz(a["rotations"])
    k = (header.sh_degree + 1) ** 2
    sh = np.empty((header.count, k, 3), np.float32)
    sh[:, 0] = dc
    if k > 1:
        sh[:, 1:] = ((a["sh"].astype(np.float32) - 128.0) / 128.0).reshape(-1, k - 1, 3)
    if stored.stored != spz_axes.SCENE_AXES:
        spz_axes.flip_axes(means, quats, sh, spz_axes.axis_signs(stored.stored))
    return (means, quats, log_scales, logits, sh), stored


def decode(path, data: bytes, axes: str | None = None) -> tuple[np.ndarray, ...]:
    """Raw scene arrays ``(means (N, 3), quats (N, 4) w-first, log_scales (N, 3),
    opacity_logits (N,), sh (N, K, 3))`` of an SPZ file's bytes, in RDF axes.

    The stored axes are what the file's extension records, else ``axes`` ("rub" or "rdf"),
    else the version's default (:func:`.spz_axes.resolve`).
    """
    return decode_with_axes(path, data, axes)[0]


@reader_guard
def read_spz(path: Path, drop_invalid: bool = False, axes: str | None = None,
             allow_empty: bool = False) -> Scene:
    """Load an SPZ file as a 3DGS :class:`Scene`; ``axes`` as in :func:`decode`; a file of
    zero points is refused unless ``allow_empty`` (see :func:`splatgl.load_scene`)."""
    raw = decode(path, _binary.read_bytes(path), axes)
    if allow_empty and raw[0].shape[0] == 0:  # nothing to validate
        return Scene(*raw, SplatKind.GAUSSIAN_3D)
    return activate(path, *raw, SplatKind.GAUSSIAN_3D, drop_invalid)


@reader_guard
def read(path: Path, drop_invalid: bool = False, axes: str | None = None,
         allow_empty: bool = False) -> Scene:
    """Load an SPZ file, its axes decided as :mod:`.spz_axes` describes."""
    return read_spz(path, drop_invalid, axes, allow_empty)
