"""GPU storage of a scene's attributes (``--gpu-storage``): bytes per splat, the compact
layout's encoder, its NumPy twin of shaders/lib/dequantise.glsl, and the error bounds it implies.

Compact layout (:attr:`GpuStorage.COMPACT`): two uvec4 (:data:`COMPACT_WORDS` uint32) per splat
in one storage buffer, then the SH coefficients 1.. as float16 (as :attr:`GpuStorage.HALF_SH`):

====  =======================================================================================
word  content
====  =======================================================================================
0-2   mean - scene anchor, float32 bits (positions keep full precision: the camera's distance
      to a splat far from the anchor would lose pixels with float16)
3     opacity, unorm with :data:`~splatgl.constants.COMPACT_OPACITY_BITS` (16) bits (bits 0-15),
      and the third rotation component (bits 16-30)
4     rotation, smallest-three: the three smaller components of the unit quaternion (w, x, y, z)
      with the largest made >= 0, each in [-1/sqrt 2, 1/sqrt 2] as a
      :data:`~splatgl.constants.COMPACT_QUAT_BITS` (15)-bit unorm: the first two here (bits
      0-14, 15-29), the third in word 3; the index of the largest in bits 30-31
5-7   float16 pairs (low half first, as GLSL's packHalf2x16): (scale.x, scale.y),
      (scale.z, dc.r), (dc.g, dc.b); scales are stored in units of ``2^e`` per scene
      (:func:`scale_exponent`) so the largest lands at or below 2^15, inside float16's range
====  =======================================================================================

The twin decodes in float64 what the shader decodes in float32; the two agree to float32
rounding (tests/gl/test_storage.py renders the twin-decoded scene in float32 storage against the
compact render).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..constants import COMPACT_OPACITY_BITS, COMPACT_QUAT_BITS, SH_C0, sh_coeff_count
from ..scene.quaternion import half_step_rotation_deg, smallest_three
from ..scene.settings import GpuStorage

#: uint32 words per splat of the compact layout (two uvec4).
COMPACT_WORDS = 8
#: Bytes per splat of the float32 layout's four vec4 buffers (mean+opacity, rotation, scale, DC).
FLOAT32_BASE_BYTES = 64
#: Largest power of two a stored float16 scale may reach (float16's largest finite is 65504).
HALF_MAX_EXP = 15
#: float16: 11 significant bits (relative rounding error 2^-11); subnormal step 2^-24, so the
#: absolute error below the normal range (2^-14) is at most 2^-25.
HALF_RELATIVE = 2.0 ** -11
HALF_SUBNORMAL_ABS = 2.0 ** -25
#: Largest smallest-three component.
_QUAT_RANGE = math.sqrt(0.5)
_QUAT_LEVELS = (1 << COMPACT_QUAT_BITS) - 1
_OPACITY_LEVELS = (1 << COMPACT_OPACITY_BITS) - 1


def gpu_bytes_per_splat(storage: GpuStorage, sh_degree: int) -> int:
    """Bytes each splat takes in the scene's storage buffers (excluding per-buffer padding)."""
    rest = (sh_coeff_count(sh_degree) - 1) * 3
    storage = GpuStorage(storage)
    if storage is GpuStorage.FLOAT32:
        return FLOAT32_BASE_BYTES + 4 * rest
    base = 4 * COMPACT_WORDS if storage is GpuStorage.COMPACT else FLOAT32_BASE_BYTES
    return base + 2 * rest


def scale_exponent(log_scales: np.ndarray, block: int = 1 << 16) -> int:
    """The per-scene exponent ``e``: scales are stored as float16 of ``scale / 2^e``, with ``e``
    the smallest integer putting the largest finite scale at or below ``2^15`` (0 when none is
    finite).  ``log_scales``: (N, S) natural-log scales as the scene holds them; read ``block``
    rows at a time (no full-size temporary)."""
    top = -math.inf
    for start in range(0, len(log_scales), block):
        part = np.asarray(log_scales[start:start + block])
        finite = np.isfinite(part)
        if finite.any():
            top = max(top, float(part[finite].max()))
    if not math.isfinite(top):
        return 0
    return int(np.clip(math.ceil(top / math.log(2.0)) - HALF_MAX_EXP, -100, 100))


def _half_bits(values: np.ndarray) -> np.ndarray:
    """float16 bit patterns (uint32) of ``values``, rounded to nearest."""
    return np.asarray(values, np.float64).astype(np.float16).view(np.uint16).astype(np.uint32)


def encode_compact(relative_means: np.ndarray, opacities: np.ndarray, rotations: np.ndarray,
                   scales: np.ndarray, dc: np.ndarray, exponent: int) -> np.ndarray:
    """The compact words of ``m`` splats: (m, 8) uint32 (layout in the module docstring).

    Args: ``relative_means`` (m, 3) float32 means - anchor; ``opacities`` (m,) in [0, 1];
    ``rotations`` (m, 4) unit quaternions (w, x, y, z); ``scales`` (m, 3) or (m, 2) (surfels,
    stored with scale.z = 0) world units; ``dc`` (m, 3) SH degree-0 coefficients;
    ``exponent`` from :func:`scale_exponent`.
    """
    m = relative_means.shape[0]
    words = np.zeros((m, COMPACT_WORDS), np.uint32)
    words[:, 0:3] = np.ascontiguousarray(relative_means, np.float32).view(np.uint32)
    o = np.clip(np.asarray(opacities, np.float64), 0.0, 1.0)
    words[:, 3] = np.rint(o * _OPACITY_LEVELS).astype(np.uint32)
    if m:
        largest, rest = smallest_three(rotations)
        k = np.rint((np.clip(rest / _QUAT_RANGE, -1.0, 1.0) * 0.5 + 0.5) * _QUAT_LEVELS).astype(np.uint32)
        words[:, 4] = k[:, 0] | (k[:, 1] << COMPACT_QUAT_BITS) | (largest.astype(np.uint32) << 30)
        words[:, 3] |= k[:, 2] << COMPACT_OPACITY_BITS
    s = np.zeros((m, 3))
    s[:, :scales.shape[1]] = np.ldexp(np.asarray(scales, np.float64), -exponent)
    h = _half_bits(np.concatenate([s, np.asarray(dc, np.float64)], axis=1))  # (m, 6)
    words[:, 5:8] = h[:, 0::2] | (h[:, 1::2] << 16)
    return words


@dataclass(frozen=True)
class CompactDecoded:
    """Decoded compact splats, float64: ``relative_means`` (m, 3), ``opacities`` (m,),
    ``rotations`` (m, 4) unit (w, x, y, z), ``scales`` (m, 3) world units, ``dc`` (m, 3)."""

    relative_means: np.ndarray
    opacities: np.ndarray
    rotations: np.ndarray
    scales: np.ndarray
    dc: np.ndarray


def decode_compact(words: np.ndarray, exponent: int) -> CompactDecoded:
    """Twin of shaders/lib/dequantise.glsl: (m, 8) uint32 words -> :class:`CompactDecoded`."""
    words = np.asarray(words, np.uint32).reshape(-1, COMPACT_WORDS)
    m = words.shape[0]
    means = np.ascontiguousarray(words[:, 0:3]).view(np.float32).astype(np.float64)
    opacities = (words[:, 3] & _OPACITY_LEVELS) / _OPACITY_LEVELS
    k = np.stack([words[:, 4], words[:, 4] >> COMPACT_QUAT_BITS, words[:, 3] >> COMPACT_OPACITY_BITS],
                 axis=1) & _QUAT_LEVELS
    c = (k / _QUAT_LEVELS * 2.0 - 1.0) * _QUAT_RANGE
    largest = (words[:, 4] >> 30).astype(np.intp)
    q = np.zeros((m, 4))
    keep = np.ones((m, 4), bool)
    keep[np.arange(m), largest] = False
    q[keep] = c.ravel()
    q[np.arange(m), largest] = np.sqrt(np.maximum(0.0, 1.0 - (c * c).sum(axis=1)))
    pairs = words[:, 5:8]
    h = np.stack([pairs & 0xFFFF, pairs >> 16], axis=2).reshape(m, 6)
    halves = h.astype(np.uint16).view(np.float16).astype(np.float64)
    return CompactDecoded(means, opacities, q, np.ldexp(halves[:, 0:3], exponent), halves[:, 3:6])


@dataclass(frozen=True)
class CompactBounds:
    """A priori bounds of the compact layout's round trip for one scene.

    ``opacity``: absolute; ``rotation_deg``: degrees; ``scale_relative``: relative, for scales
    at or above ``scale_floor`` (world units; below it the error is at most ``scale_absolute``);
    ``color``: SH DC colour in 0-1 units (``SH_C0 |delta dc|``); ``sh_rest``: absolute per
    coefficient (float16, as HALF_SH).  Positions are stored exactly (float32, as FLOAT32).
    """

    opacity: float
    rotation_deg: float
    scale_relative: float
    scale_floor: float
    scale_absolute: float
    color: float
    sh_rest: float


def compact_bounds(sh: np.ndarray, exponent: int) -> CompactBounds:
    """Bounds for a scene with SH coefficients ``sh`` (N, K, 3) and scale ``exponent``."""
    sh = np.asarray(sh)
    dc_max = float(np.abs(sh[:, 0]).max()) if sh.size else 0.0
    rest_max = float(np.abs(sh[:, 1:]).max()) if sh.shape[1] > 1 and sh.size else 0.0
    return CompactBounds(
        opacity=0.5 / _OPACITY_LEVELS,
        rotation_deg=half_step_rotation_deg(0.5 * 2.0 * _QUAT_RANGE / _QUAT_LEVELS),
        scale_relative=HALF_RELATIVE,
        scale_floor=math.ldexp(1.0, exponent - 14),
        scale_absolute=math.ldexp(HALF_SUBNORMAL_ABS, exponent),
        color=SH_C0 * max(dc_max * HALF_RELATIVE, HALF_SUBNORMAL_ABS),
        sh_rest=max(rest_max * HALF_RELATIVE, HALF_SUBNORMAL_ABS),
    )
