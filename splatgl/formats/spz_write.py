"""Writer of Niantic SPZ (``*.spz``), versions 2 and 3 (gzip), read back by :mod:`.spz`.

Layout and decoding are described in :mod:`splatgl.formats.spz`.  Axes (:mod:`.spz_axes`):
``axes`` "rub" or "rdf", by default RUB for version 3 (the SPZ specification: y and z negated
against the scene's RDF, with the matching SH signs) and RDF as is for version 2 (what version 2
files hold).  Every file but a version 3 one in RUB also records its axes in an
``SPZ_ADOBE_coordinate_system`` extension record (flags bit 1, after the arrays), so that
readers following the specification and splatgl's own version defaults both read it right.
Quantisation (constants in :mod:`splatgl.formats.quantise`):

- positions: 24-bit fixed point with 12 fractional bits (fewer when the scene's extent needs
  them: the header records the count), error at most half a step per axis;
- opacity 8 bits; colour ``round(255 (0.15 f_dc + 0.5))``; log-scale ``round(16 (s + 10))``,
  each clipped to a byte (values outside the range lose the distance clipped);
- rotation: version 2 (x, y, z) bytes with ``w >= 0``; version 3 smallest three, 9 bits + sign;
- SH degrees 1-3: ``round(128 v + 128)``, all 8 bits kept.
"""

from __future__ import annotations

import gzip
import math
import struct

import numpy as np

from ..errors import SceneFormatError
from ..scene.splats import Scene, SplatKind
from . import quantise as qz
from . import spz_axes
from .spz import FLAG_EXTENSIONS, HEADER_FORMAT, MAGIC

NAME = "spz"
EXTENSIONS = (".spz",)
#: Versions this module writes; the default is the newest gzip version.
VERSIONS = (2, 3)
DEFAULT_VERSION = 3
#: Header flag bit 0: the scene was trained with antialiasing (mip-splatting's 2D filter).
FLAG_ANTIALIASED = 0x1
#: gzip level: 6 is zlib's default balance of speed and size.
GZIP_LEVEL = 6


def fractional_bits(means: np.ndarray, path=None) -> int:
    """Fractional bits of the 24-bit fixed point: the default, or fewer so ``max |x|`` fits
    (refused, naming ``path``, when nothing fits)."""
    biggest = float(np.abs(np.asarray(means, np.float64)).max()) if len(means) else 0.0
    bits = qz.SPZ_FRACTIONAL_BITS
    while bits > 0 and biggest * 2.0 ** bits >= (1 << 23) - 1:
        bits -= 1
    if biggest * 2.0 ** bits >= (1 << 23) - 1:
        raise SceneFormatError(path, f"positions up to {biggest:g} do not fit SPZ's 24-bit fixed "
                                     "point even with 0 fractional bits", "position")
    return bits


def _byte(values: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(values), 0, 255).astype(np.uint8)


def _rotations_xyz(q: np.ndarray) -> np.ndarray:
    """(N, 3) uint8 (x, y, z) of unit (w, x, y, z) quaternions with w made >= 0 (version 2)."""
    q = q * np.where(q[:, :1] < 0.0, -1.0, 1.0)
    return _byte((q[:, 1:] + 1.0) * 127.5)


def _rotations_smallest3(q: np.ndarray) -> np.ndarray:
    """(N, 4) uint8 little-endian smallest-three words of unit (w, x, y, z) (version 3)."""
    largest, rest = qz.smallest_three(q[:, [1, 2, 3, 0]])  # SPZ orders (x, y, z, w)
    top = (1 << qz.SPZ_QUAT_BITS) - 1
    word = largest.astype(np.uint32) << np.uint32(30)
    shift = 0
    for i in range(2, -1, -1):  # the last stored component sits in the low bits
        mag = np.clip(np.rint(np.abs(rest[:, i]) * math.sqrt(2.0) * top), 0, top).astype(np.uint32)
        sign = (rest[:, i] < 0.0).astype(np.uint32)
        word |= (mag | (sign << np.uint32(qz.SPZ_QUAT_BITS))) << np.uint32(shift)
        shift += qz.SPZ_QUAT_BITS + 1
    return word.astype("<u4").view(np.uint8).reshape(-1, 4)


def stored_axes(version: int, axes: str | None = None) -> str:
    """The axes a file of ``version`` is written in: ``axes`` ("rub"/"rdf") or the default."""
    axes = spz_axes.check_choice(axes)
    return spz_axes.default_axes(version) if axes is None else axes.upper()


def encode(scene: Scene, version: int = DEFAULT_VERSION, antialiased: bool = False,
           axes: str | None = None, path=None) -> bytes:
    """The uncompressed SPZ body (header, attribute arrays, extension record) of ``scene``."""
    if version not in VERSIONS:
        raise SceneFormatError(path, f"cannot write SPZ version {version} (writable: "
                                     f"{', '.join(map(str, VERSIONS))})", "version")
    if scene.kind is not SplatKind.GAUSSIAN_3D:
        raise SceneFormatError(path, "SPZ stores 3D Gaussians only; cannot write a 2DGS surfel "
                                     "scene (write .ply instead)", "scale")
    stored = stored_axes(version, axes)
    means = scene.means.astype(np.float64)
    q = scene.rotations.astype(np.float64)
    sh = scene.sh.astype(np.float64)
    if stored != spz_axes.SCENE_AXES:
        spz_axes.flip_axes(means, q, sh, spz_axes.axis_signs(stored))
    rest = sh[:, 1:]
    record = b"" if (version, stored) == (3, spz_axes.SPEC_AXES) else spz_axes.encode_record(stored)
    bits = fractional_bits(means, path)
    fixed = np.rint(means * 2.0 ** bits).astype(np.int64) & 0xFFFFFF
    positions = np.stack([(fixed >> s) & 0xFF for s in (0, 8, 16)], axis=-1).astype(np.uint8)
    alphas = _byte(scene.opacities.astype(np.float64) * 255.0)
    colours = _byte((scene.sh[:, 0].astype(np.float64) * qz.SPZ_COLOR_SCALE + 0.5) * 255.0)
    scales = _byte((scene.log_scales.astype(np.float64) + qz.SPZ_SCALE_OFFSET) * qz.SPZ_SCALE_STEPS)
    rotations = _rotations_smallest3(q) if version >= 3 else _rotations_xyz(q)
    sh = _byte(rest * qz.SPZ_SH_SCALE + 128.0)
    flags = (FLAG_ANTIALIASED if antialiased else 0) | (FLAG_EXTENSIONS if record else 0)
    header = struct.pack(HEADER_FORMAT, MAGIC, version, scene.count, scene.sh_degree, bits,
                         flags, 0)
    parts = [positions, alphas, colours, scales, rotations, sh]
    return header + b"".join(np.ascontiguousarray(p).tobytes() for p in parts) + record


def write(path, scene: Scene, version: int = DEFAULT_VERSION, antialiased: bool = False,
          axes: str | None = None) -> None:
    """Write ``scene`` as a gzip SPZ file of ``version`` (2 or 3) in ``axes`` (see
    :func:`stored_axes`)."""
    body = encode(scene, version, antialiased, axes, path=path)
    with open(path, "wb") as fh:
        fh.write(gzip.compress(body, GZIP_LEVEL, mtime=0))


def error_bounds(scene: Scene, version: int = DEFAULT_VERSION, axes: str | None = None) -> dict:
    """Per-attribute round-trip error bounds of a file of ``version`` in ``axes`` (see
    :mod:`splatgl.formats.quantise`)."""
    bits = fractional_bits(scene.means)
    position = math.sqrt(3.0) * 0.5 * 2.0 ** -bits + qz.position_slack(scene.means)
    dc_lo, dc_hi = -0.5 / qz.SPZ_COLOR_SCALE, 0.5 / qz.SPZ_COLOR_SCALE
    dc_step = 0.5 / 255.0 / qz.SPZ_COLOR_SCALE + qz.clip_excess(scene.sh[:, 0], dc_lo, dc_hi)
    log_lo = -qz.SPZ_SCALE_OFFSET
    log_hi = 255.0 / qz.SPZ_SCALE_STEPS - qz.SPZ_SCALE_OFFSET
    log_step = 0.5 / qz.SPZ_SCALE_STEPS + qz.clip_excess(scene.log_scales, log_lo, log_hi)
    if version >= 3:
        rotation = qz.half_step_rotation_deg(0.5 / ((1 << qz.SPZ_QUAT_BITS) - 1) / math.sqrt(2.0))
    else:
        rotation = qz.xyz_rotation_deg(0.5 / 127.5)
    rest = None
    if scene.sh_degree > 0:
        s = qz.SPZ_SH_SCALE
        stored = scene.sh[:, 1:]
        signs = spz_axes.axis_signs(stored_axes(version, axes))
        if stored.size and (signs != 1).any():
            # the bytes hold the other axes' SH signs, and the byte range clips those
            stored = stored * spz_axes.sh_signs(signs, stored.shape[1])[None, :, None]
        rest = 0.5 / s + qz.clip_excess(stored, -1.0, 127.0 / s) + 1e-6
    return {
        "position": position,
        "scale": qz.relative_scale(log_step) * (1 + 1e-6) + 1e-6,
        "opacity": 0.5 / 255.0 + 1e-6,
        "rotation": rotation,
        "color": qz.colour_from_dc(dc_step) * (1 + 1e-6) + 1e-7,
        "sh_rest": rest,
    }
