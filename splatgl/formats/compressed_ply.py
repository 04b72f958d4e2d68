"""PlayCanvas / SuperSplat compressed PLY (``*.compressed.ply``).

A binary PLY with up to three elements::

    element chunk M     float min_x min_y min_z max_x max_y max_z
                        float min_scale_x .. min_scale_z max_scale_x .. max_scale_z
                        [float min_r min_g min_b max_r max_g max_b]   (optional colour bounds)
    element vertex N    uint packed_position packed_rotation packed_scale packed_color
    [element sh N       uchar f_rest_0 .. f_rest_{3(K-1)-1}]           (optional, channel-major)

Vertex ``i`` belongs to chunk ``i // 256``, whose min/max bound its values.  Decoding
(``unorm(v, bits) = v / (2^bits - 1)``, fields taken from the most significant bits down):

- position: 11-10-11 bits (x, y, z) -> ``min + (max - min) t`` (world units).
- scale: 11-10-11 bits -> ``min_scale + (max_scale - min_scale) t``; the bounds are log-scales.
- rotation: bits 31..30 index the largest of (w, x, y, z); the other three, in order, are 10-bit
  ``(t - 0.5) sqrt(2)`` (range +-1/sqrt(2)); the largest is ``sqrt(1 - a^2 - b^2 - c^2)``.
- colour: 8-8-8-8 bits (r, g, b, alpha); rgb -> ``min_c + (max_c - min_c) t`` when the chunk has
  colour bounds; ``f_dc = (rgb - 0.5) / SH_C0``; opacity logit ``log(a / (1 - a))``.
- sh: byte ``b`` -> ``(b + 0.5) / 32 - 4`` (centre of the writer's ``trunc((v / 8 + 0.5) 256)``
  bin, range [-4, 4)), ``f_rest`` channel-major as in INRIA PLY.

Verified on the real files: biker's positions, colours, opacities and (w, x, y, z) rotations
agree with the same scene's SPZ (``spz/biker_v4.spz``) to quantisation (see the tests).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..constants import SH_C0
from ..errors import SceneFormatError
from ..scene.splats import Scene, SplatKind, activate, rest_to_sh, sh_degree_from_rest_count
from . import _binary
from ._memory import check_memory
from ._messages import quote, reader_guard

NAME = "compressed_ply"
EXTENSIONS = (".compressed.ply",)
#: Vertices per chunk (each chunk carries one set of min/max bounds).
CHUNK_SIZE = 256
#: The header must end within this many bytes.
MAX_HEADER_BYTES = 1 << 16

_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
_POSITION = ("min_x", "min_y", "min_z", "max_x", "max_y", "max_z")
_SCALE = ("min_scale_x", "min_scale_y", "min_scale_z", "max_scale_x", "max_scale_y",
          "max_scale_z")
_COLOUR = ("min_r", "min_g", "min_b", "max_r", "max_g", "max_b")
_PACKED = ("packed_position", "packed_rotation", "packed_scale", "packed_color")
#: For each index of the largest component, where the three stored components go in (w, x, y, z).
_OTHERS = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])


@dataclass
class _Element:
    name: str
    count: int
    props: list[tuple[str, str]] = field(default_factory=list)  # (name, numpy type code)


def sniff(head: bytes) -> bool:
    """True for a PLY whose header (within ``head``) declares an ``element chunk``."""
    if not head.startswith(b"ply"):
        return False
    header = head.split(b"end_header", 1)[0]
    return b"\nelement chunk " in header.replace(b"\r\n", b"\n")


def _parse_header(path, data: bytes) -> tuple[list[_Element], str, int]:
    """(elements, byte order '<' or '>', offset of the body) from the PLY header."""
    end = data.find(b"end_header", 0, MAX_HEADER_BYTES)
    if not data.startswith(b"ply") or end < 0:
        raise SceneFormatError(path, f"not a PLY file, or no 'end_header' in the first "
                                     f"{MAX_HEADER_BYTES} bytes")
    body = data.find(b"\n", end)
    if body < 0:
        raise SceneFormatError(path, "truncated: nothing after 'end_header'")
    try:
        lines = data[:end].decode("ascii").replace("\r\n", "\n").split("\n")[1:]
    except UnicodeDecodeError:
        raise SceneFormatError(path, "PLY header is not ASCII text") from None
    order, elements = None, []
    for number, line in enumerate(lines, start=2):
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "format" and len(words) >= 2:
            order = {"binary_little_endian": "<", "binary_big_endian": ">"}.get(words[1])
            if order is None:
                raise SceneFormatError(path, f"compressed PLY must be binary, not "
                                             f"{quote(words[1])}", "format")
        elif words[0] == "element" and len(words) == 3 and words[2].isdigit():
            elements.append(_Element(words[1], int(words[2])))
        elif words[0] == "property" and len(words) == 3 and elements:
            if words[1] not in _TYPES:
                raise SceneFormatError(path, f"header line {number}: unknown type "
                                             f"{quote(words[1])}", words[2])
            elements[-1].props.append((words[2], _TYPES[words[1]]))
        else:
            raise SceneFormatError(path, f"header line {number} not understood: {quote(line)}")
    if order is None:
        raise SceneFormatError(path, "PLY header has no 'format' line")
    return elements, order, body + 1


def _read_elements(path, data: bytes) -> dict[str, np.ndarray]:
    """Every element as a structured array (read-only views of ``data``), sizes checked first.

    The elements must fill the body exactly: a count off by one or a property of another
    type than the data was written with leaves bytes over or missing, and is an error.
    """
    elements, order, offset = _parse_header(path, data)
    out = {}
    for elem in elements:
        label = quote(elem.name)
        if elem.name in out:
            raise SceneFormatError(path, f"element {label} is declared twice", elem.name)
        if not elem.props:
            raise SceneFormatError(path, f"element {label} declares no properties", elem.name)
        names = [name for name, _ in elem.props]
        if len(set(names)) != len(names):
            raise SceneFormatError(path, f"element {label} repeats a property name", elem.name)
        dtype = np.dtype([(name, order + code) for name, code in elem.props])
        size = _binary.check_fits(path, elem.count, dtype.itemsize, len(data) - offset,
                                  f"element {label} ({elem.count} rows)", elem.name)
        out[elem.name] = np.frombuffer(data, dtype, elem.count, offset)
        offset += size
    if offset != len(data):
        raise SceneFormatError(
            path, f"{len(data) - offset} bytes after the last element: the header declares "
            f"{offset} bytes in all, the file holds {len(data)} (an element count or a property "
            "type does not match the body)")
    return out


def _columns(path, rows: np.ndarray, element: str, names: tuple[str, ...],
             kind: str = "f") -> np.ndarray:
    """(n, len(names)) float64 columns of ``rows``; a missing one, or one whose type is not of
    NumPy ``kind`` ('f' float, 'u' unsigned), is an error naming it."""
    have = rows.dtype.names or ()
    missing = [name for name in names if name not in have]
    if missing:
        raise SceneFormatError(path, f"element '{element}' lacks {', '.join(missing)}",
                               missing[0])
    for name in names:
        if rows.dtype[name].kind != kind:
            want = {"f": "float", "u": "unsigned integer"}[kind]
            raise SceneFormatError(path, f"element '{element}': property type "
                                         f"{rows.dtype[name].name}, expected {want}", name)
    return np.stack([rows[name].astype(np.float64) for name in names], axis=1)


def _bounds(path, chunks: np.ndarray, names: tuple[str, ...]) -> np.ndarray:
    """(M, 6) float64 chunk bounds ``names``; a NaN or Inf is an error naming chunk and field."""
    cols = _columns(path, chunks, "chunk", names)
    bad = ~np.isfinite(cols)
    if bad.any():
        row, col = (int(i[0]) for i in np.nonzero(bad))
        raise SceneFormatError(path, f"chunk {row} (of {cols.shape[0]}) holds "
                                     f"{cols[row, col]}; bounds must be finite", names[col])
    return cols


def _lerp(bounds: np.ndarray, chunk: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``min + (max - min) t`` per vertex; ``bounds`` (M, 6) is (min xyz, max xyz) per chunk."""
    lo, hi = bounds[chunk, :3], bounds[chunk, 3:]
    return lo + (hi - lo) * t


def _unpack_111011(packed: np.ndarray) -> np.ndarray:
    """(N, 3) float64 in [0, 1] from 11-10-11-bit packed uint32 (x in the top bits)."""
    return np.stack([_binary.unorm(packed, 21, 11), _binary.unorm(packed, 11, 10),
                     _binary.unorm(packed, 0, 11)], axis=1)


def unpack_rotation(packed: np.ndarray) -> np.ndarray:
    """(N, 4) float64 unit quaternions (w, x, y, z) from 2-10-10-10 smallest-three uint32."""
    packed = np.asarray(packed, np.uint32)
    abc = np.stack([_binary.unorm(packed, 20, 10), _binary.unorm(packed, 10, 10),
                    _binary.unorm(packed, 0, 10)], axis=1)
    abc = (abc - 0.5) * math.sqrt(2.0)
    largest = (packed >> np.uint32(30)).astype(np.intp)
    quats = np.empty((packed.shape[0], 4))
    rows = np.arange(packed.shape[0])
    quats[rows[:, None], _OTHERS[largest]] = abc
    quats[rows, largest] = np.sqrt(np.maximum(0.0, 1.0 - (abc * abc).sum(axis=1)))
    return quats


def _sh(path, sh_rows: np.ndarray | None, n: int, dc: np.ndarray) -> np.ndarray:
    """(N, K, 3) SH from f_dc and the optional ``sh`` element of uchar ``f_rest_*``."""
    if sh_rows is None:
        return dc[:, None, :]
    if sh_rows.shape[0] != n:
        raise SceneFormatError(path, f"element 'sh' has {sh_rows.shape[0]} rows, expected {n} "
                                     "(one per vertex)", "sh")
    names = [f"f_rest_{i}" for i in range(len(sh_rows.dtype.names))]
    sh_degree_from_rest_count(path, len(names))
    rest = _columns(path, sh_rows, "sh", tuple(names), "u")
    if sh_rows.dtype.itemsize != len(names):
        raise SceneFormatError(path, "element 'sh': properties must be uchar", "sh")
    return rest_to_sh(dc, (rest + 0.5) / 32.0 - 4.0)


def decode(path, data: bytes) -> tuple[np.ndarray, ...]:
    """Raw scene arrays ``(means, quats, log_scales, opacity_logits, sh)`` of a compressed PLY.

    Shapes (N, 3), (N, 4) w-first, (N, 3) log-scales, (N,) logits, (N, K, 3); float32 except
    quats and means (float64 before :func:`activate` casts them).
    """
    elements = _read_elements(path, data)
    for name in ("chunk", "vertex"):
        if name not in elements:
            raise SceneFormatError(path, f"no 'element {name}' in the header", name)
    chunks, vertices = elements["chunk"], elements["vertex"]
    n = vertices.shape[0]
    needed = -(-n // CHUNK_SIZE)
    if chunks.shape[0] < needed:
        raise SceneFormatError(path, f"{chunks.shape[0]} chunks for {n} vertices; expected "
                                     f"{needed} (one per {CHUNK_SIZE})", "chunk")
    _columns(path, vertices[:0], "vertex", _PACKED, "u")  # names and types only
    for name in _PACKED:
        if vertices.dtype[name].itemsize != 4:
            raise SceneFormatError(path, f"element 'vertex': property type "
                                         f"{vertices.dtype[name].name}, expected uint", name)
    sh_rows = elements.get("sh")
    n_rest = len(sh_rows.dtype.names) if sh_rows is not None else 0
    # working arrays per splat: packed words, float64 unpacked fields and their lerps
    # (measured about 145 bytes on biker), float64 + float32 copies of each SH value
    check_memory(path, n, n_rest // 3 + 1, 160 + 32 * n_rest, len(data), "vertex")
    packed = np.stack([vertices[name].astype(np.uint32) for name in _PACKED], axis=1)
    chunk = np.arange(n) // CHUNK_SIZE

    means = _lerp(_bounds(path, chunks, _POSITION), chunk, _unpack_111011(packed[:, 0]))
    log_scales = _lerp(_bounds(path, chunks, _SCALE), chunk, _unpack_111011(packed[:, 2]))
    quats = unpack_rotation(packed[:, 1])
    colour = packed[:, 3]
    rgb = np.stack([_binary.unorm(colour, s, 8) for s in (24, 16, 8)], axis=1)
    if all(name in (chunks.dtype.names or ()) for name in _COLOUR):
        rgb = _lerp(_bounds(path, chunks, _COLOUR), chunk, rgb)
    logits = _binary.logit(_binary.unorm(colour, 0, 8))
    dc = ((rgb - 0.5) / SH_C0).astype(np.float32)
    sh = _sh(path, sh_rows, n, dc)
    return means, quats, log_scales.astype(np.float32), logits, sh


@reader_guard
def read(path: Path, drop_invalid: bool = False) -> Scene:
    """Load a compressed PLY as a 3DGS :class:`Scene` (values through :func:`activate`)."""
    means, quats, log_scales, logits, sh = decode(path, _binary.read_bytes(path))
    return activate(path, means, quats, log_scales, logits, sh, SplatKind.GAUSSIAN_3D,
                    drop_invalid)
