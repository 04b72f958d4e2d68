"""Which axes an SPZ file stores, how splatgl tells, and the conversion to the scene's RDF.

splatgl's :class:`~splatgl.scene.splats.Scene` uses 3DGS PLY axes, RDF (x right, y down, z forward).
The SPZ specification (nianticlabs/spz README, "Coordinate System", since April 2025) says an
SPZ file stores RUB (x right, y up, z back: OpenGL, three.js) unless the vendor extension
``SPZ_ADOBE_coordinate_system`` (type ``0xADBE0003``, payload one ``uint32``, the library's
``CoordinateSystem`` value) names another system.  Extension records ``[uint32 type][uint32
byteLength][payload]`` follow the 32-byte header of a version 4 file (up to
``tocByteOffset``) and the attribute arrays of a gzip (version 1-3) body, and header flags bit
1 (``0x2``) says they are there.  Nothing else in a file (version, fractionalBits, the other
flag bit) says which axes it holds, and the official library converts only when its caller
names a system (``PackOptions.from`` / ``UnpackOptions.to``; ``UNSPECIFIED``, the default,
stores and loads as is: its own ``ply_to_spz`` tool writes PLY's RDF unconverted).

What writers do (checked against the files each writes, see docs/formats.md):

- splat-transform 2.1-2.7 (official library, ``from: RDF``): RUB, as the specification says;
- splat-transform 3.x (official library, ``from: UNSPECIFIED``; its reader decodes raw): RDF,
  versions 3 and 4 alike, with no extension: no file field tells these files from the
  specification's, so they need ``axes="rdf"`` (``--spz-axes rdf``);
- PlayCanvas's ``biker.spz`` (version 4), splat-transform's ``minimal-v3/-v4.spz``: RUB;
- spz-js 1.2 and the gzip version 2 fixtures (written before the specification named axes):
  RDF as stored;
- splatgl: version 3 in RUB without an extension; any other choice (version 2, ``axes="rdf"``)
  with the extension, so that the file says what it holds.

The rule (:func:`resolve`): the extension when the file has one; else ``axes`` (the
``--spz-axes`` option); else RUB for versions 3-4 (the specification) and the stored axes for
versions 1-2 (what every version 2 file at hand holds).  Systems are the library's 16: the 8
of the standard family (each axis flipped or not) are read and written; the 8 "rotated" ones
(y and z swapped, a quarter turn about x) are refused.
"""

from __future__ import annotations

import struct
import warnings
from dataclasses import dataclass

import numpy as np

from ..errors import SceneFormatError, SplatglError

#: The official library's ``CoordinateSystem`` names, by enum value (0 = UNSPECIFIED).
COORDINATE_SYSTEMS = ("UNSPECIFIED", "LDB", "RDB", "LUB", "RUB", "LDF", "RDF", "LUF", "RUF",
                      "LFD", "RFD", "LFU", "RFU", "LBD", "RBD", "LBU", "RBU")
#: The axes the SPZ specification stores, and the axes of splatgl's scenes.
SPEC_AXES = "RUB"
SCENE_AXES = "RDF"
#: ``--spz-axes`` choices: the axes assumed for a file that records none.
CHOICES = ("rub", "rdf")
EXT_SAFE_ORBIT_CAMERA = 0xADBE0002
EXT_COORDINATE_SYSTEM = 0xADBE0003
EXTENSION_NAMES = {EXT_SAFE_ORBIT_CAMERA: "SPZ_ADOBE_safe_orbit_camera",
                   EXT_COORDINATE_SYSTEM: "SPZ_ADOBE_coordinate_system"}
RECORD_HEAD = struct.Struct("<II")
#: Most extension bytes splatgl reads after a gzip body (records are a few bytes each).
MAX_EXTENSION_BYTES = 1 << 16
#: Sign of each letter's direction in RDF: R/L along x, D/U along y, F/B along z.
_SIGNS = {"R": 1.0, "L": -1.0, "D": 1.0, "U": -1.0, "F": 1.0, "B": -1.0}
#: Odd (1) or even (0) in (x, y, z) of the SH basis functions of degrees 1-3, 3DGS order:
#: y z x | xy yz (3zz-1) xz (xx-yy) | y(3xx-yy) xyz y(5zz-1) z(5zz-3) x(5zz-1) z(xx-yy) x(xx-3yy).
SH_PARITY = np.array([
    [0, 1, 0], [0, 0, 1], [1, 0, 0],
    [1, 1, 0], [0, 1, 1], [0, 0, 0], [1, 0, 1], [0, 0, 0],
    [0, 1, 0], [1, 1, 1], [0, 1, 0], [0, 0, 1], [1, 0, 0], [0, 0, 1], [1, 0, 0]], np.int8)


def axis_signs(name: str) -> np.ndarray:
    """(3,) float64 signs taking a standard-family system's coordinates to RDF (its own inverse)."""
    return np.array([_SIGNS[c] for c in name], np.float64)


def sh_signs(signs: np.ndarray, count: int) -> np.ndarray:
    """(count,) float32 factors of the first ``count`` degree 1-3 SH coefficients when each axis
    is multiplied by ``signs``: a basis function odd in an axis changes sign with it."""
    return np.prod(np.where(SH_PARITY[:count] == 1, np.asarray(signs)[None, :], 1.0),
                   axis=1).astype(np.float32)


def flip_axes(means: np.ndarray, quats: np.ndarray, sh: np.ndarray, signs) -> None:
    """Multiply each axis by ``signs`` in place: means (N, 3), quats (N, 4) w-first, sh (N, K, 3).

    A rotation R becomes M R M (M = diag(signs)), whose quaternion vector is det(M) M v; the
    scales are unchanged.  The library's ``coordinateConverter`` uses the same factors.
    """
    signs = np.asarray(signs, np.float64)
    means *= signs
    quats[:, 1:] *= np.prod(signs) * signs
    if sh.shape[1] > 1:
        sh[:, 1:] *= sh_signs(signs, sh.shape[1] - 1)[None, :, None]


def parse_records(path, blob: bytes) -> list[tuple[int, bytes]]:
    """``(type, payload)`` of each extension record in ``blob``; one line on a cut-off record."""
    records, offset = [], 0
    while offset < len(blob):
        if len(blob) - offset < RECORD_HEAD.size:
            raise SceneFormatError(path, f"{len(blob) - offset} stray bytes where an extension "
                                         "record (8-byte type and length) should start",
                                   "extensions")
        kind, size = RECORD_HEAD.unpack_from(blob, offset)
        offset += RECORD_HEAD.size
        if size > len(blob) - offset:
            raise SceneFormatError(path, f"extension record 0x{kind:08x} claims {size} bytes, "
                                         f"only {len(blob) - offset} follow", "extensions")
        records.append((kind, blob[offset:offset + size]))
        offset += size
    return records


def encode_record(name: str) -> bytes:
    """The ``SPZ_ADOBE_coordinate_system`` record naming ``name`` (e.g. "RDF")."""
    return RECORD_HEAD.pack(EXT_COORDINATE_SYSTEM, 4) + struct.pack(
        "<I", COORDINATE_SYSTEMS.index(name))


@dataclass(frozen=True)
class Axes:
    """How an SPZ file's axes were decided: ``stored`` (e.g. "RUB"), ``source`` ("extension",
    "option" or "default"), a readable ``note`` and the names of its extension records."""

    stored: str
    source: str
    note: str
    extensions: tuple[str, ...] = ()

    def describe(self) -> str:
        """One line, e.g. ``RUB (the SPZ specification's axes; ...), converted to RDF``."""
        text = f"{self.stored} ({self.note})"
        return text + (", read as is" if self.stored == SCENE_AXES else
                       f", converted to {SCENE_AXES}")

    def as_dict(self) -> dict:
        return {"stored": self.stored, "read_as": SCENE_AXES, "source": self.source,
                "note": self.note, "extensions": list(self.extensions),
                "description": self.describe()}


def check_choice(axes: str | None) -> str | None:
    """``axes`` lower-cased if it is None, "rub" or "rdf"; else a :class:`SplatglError`."""
    if axes is None:
        return None
    if not isinstance(axes, str) or axes.lower() not in CHOICES:
        raise SplatglError(f"--spz-axes must be one of {', '.join(CHOICES)}, got {axes!r}")
    return axes.lower()


def default_axes(version: int) -> str:
    """Axes assumed for a file of ``version`` that records none, without ``--spz-axes``."""
    return SPEC_AXES if version >= 3 else SCENE_AXES


def _recorded(path, records: list[tuple[int, bytes]]) -> str | None:
    codes = [p for kind, p in records if kind == EXT_COORDINATE_SYSTEM]
    if len(codes) > 1:
        raise SceneFormatError(path, f"{len(codes)} SPZ_ADOBE_coordinate_system records "
                                     "(at most one)", "extensions")
    if not codes:
        return None
    if len(codes[0]) != 4:
        raise SceneFormatError(path, f"SPZ_ADOBE_coordinate_system payload of {len(codes[0])} "
                                     "bytes, expected 4 (uint32)", "extensions")
    (code,) = struct.unpack("<I", codes[0])
    if code >= len(COORDINATE_SYSTEMS):
        raise SceneFormatError(path, f"SPZ_ADOBE_coordinate_system value {code} is not a "
                                     f"coordinate system (0-{len(COORDINATE_SYSTEMS) - 1})",
                               "extensions")
    name = COORDINATE_SYSTEMS[code]
    if code > 8:
        raise SceneFormatError(path, f"SPZ_ADOBE_coordinate_system {name} ({code}): the rotated "
                                     "systems (y and z swapped) are not supported; splatgl reads "
                                     "the 8 axis-flip systems (1-8)", "extensions")
    return None if code == 0 else name  # UNSPECIFIED: as if absent (the library: RUB)


def resolve(path, version: int, records: list[tuple[int, bytes]],
            axes: str | None = None) -> Axes:
    """The axes an SPZ file of ``version`` with extension ``records`` stores (module notes).

    ``axes`` ("rub"/"rdf", the ``--spz-axes`` option) applies to files that record none; for a
    file that records its axes, a different ``axes`` is ignored with a warning.
    """
    axes = check_choice(axes)
    names = tuple(EXTENSION_NAMES.get(kind, f"0x{kind:08x}") for kind, _ in records)
    recorded = _recorded(path, records)
    if recorded is not None:
        if axes is not None and axes.upper() != recorded:
            warnings.warn(f"{path}: --spz-axes {axes} ignored: the file records its axes "
                          f"({recorded}, SPZ_ADOBE_coordinate_system)", stacklevel=3)
        return Axes(recorded, "extension", "recorded by its SPZ_ADOBE_coordinate_system "
                                           "extension", names)
    if axes is not None:
        return Axes(axes.upper(), "option", f"--spz-axes {axes}; the file records no axes",
                    names)
    if version >= 3:
        return Axes(SPEC_AXES, "default", "the SPZ specification's axes; the file records "
                                          "none: --spz-axes rdf if it holds PLY axes as is", names)
    return Axes(SCENE_AXES, "default", f"version {version} files are read as stored; the file "
                                       "records no axes: --spz-axes rub if it holds RUB", names)
