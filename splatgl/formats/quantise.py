"""Quantisation constants of every lossy writer, the shared encoders, and the error bounds they imply.

One place for the numbers each writer quantises with (bits, steps, ranges) and for the bound on
the round-trip error each choice implies, in the units of :func:`splatgl.formats.convert.conversion_error`:

- ``position``: world units (Euclidean distance),
- ``scale``: relative error of the activated scale,
- ``opacity``: absolute error of the activated opacity,
- ``rotation``: degrees,
- ``color``: SH DC colour in 0-1 units (``SH_C0 |delta f_dc|``),
- ``sh_rest``: absolute error of the higher SH coefficients (None: not bounded a priori).

Bounds are per scene (they depend on its ranges) and include the clipping a format's fixed range
forces on values outside it (for example SPZ's 8-bit colour range).  A small float32 allowance
(:data:`F32_SLACK`) covers the final cast of the decoded values to float32.
"""

from __future__ import annotations

import math

import numpy as np

from ..constants import SH_C0
from ..errors import SceneFormatError
# smallest-three quaternions are shared with the GPU layout (gl/storage): defined with the
# quaternions, re-exported here for the writers (qz.smallest_three)
from ..scene.quaternion import half_step_rotation_deg, smallest_three  # noqa: F401

#: Relative allowance for float32 rounding of decoded values (a few ulps of 2^-24).
F32_SLACK = 4.0 * 2.0 ** -24

# --- SOG (PlayCanvas SOG v2) -------------------------------------------------------------------
#: Bits of each log-encoded mean coordinate (split into the means_l / means_u textures).
SOG_MEAN_BITS = 16
#: Entries of the scale and sh0 codebooks (one byte per label).
SOG_CODEBOOK_SIZE = 256
#: Bits of each stored smallest-three quaternion component.
SOG_QUAT_BITS = 8
#: Lloyd iterations of the 1D codebooks and of the SH palette k-means.
SOG_CODEBOOK_ITERATIONS = 16
SOG_KMEANS_ITERATIONS = 10
#: Quaternion tag bytes: 252 + index of the largest component (w, x, y, z).
SOG_QUAT_TAG = 252

# --- SPZ (Niantic) ----------------------------------------------------------------------------
#: Fractional bits of the 24-bit fixed-point positions (lowered for scenes too large for it).
SPZ_FRACTIONAL_BITS = 12
#: f_dc = (c / 255 - 0.5) / SPZ_COLOR_SCALE.
SPZ_COLOR_SCALE = 0.15
#: log-scale = s / SPZ_SCALE_STEPS - SPZ_SCALE_OFFSET.
SPZ_SCALE_STEPS = 16.0
SPZ_SCALE_OFFSET = 10.0
#: SH coefficient = (b - 128) / 128; splatgl writes all 8 bits (no coarser SH buckets).
SPZ_SH_SCALE = 128.0
#: Versions 3+: 9-bit magnitude (plus a sign bit) of each smallest-three component.
SPZ_QUAT_BITS = 9

# --- compressed PLY (PlayCanvas) --------------------------------------------------------------
#: Position and log-scale bits (x, y, z) inside each chunk's bounds.
CPLY_XYZ_BITS = (11, 10, 11)
#: Log-scale chunk bounds are clamped to +-this.
CPLY_SCALE_CLAMP = 20.0
#: Bits of each stored smallest-three quaternion component.
CPLY_QUAT_BITS = 10
#: SH coefficients: byte = trunc((v / 8 + 0.5) 256), range [-4, 4), read as the bin centre.
CPLY_SH_RANGE = 4.0


def xyz_rotation_deg(component_error: float) -> float:
    """Bound (degrees) for quaternions stored as (x, y, z) with ``w = sqrt(1 - |xyz|^2) >= 0``
    (SPZ versions 1-2): ``|dw| <= sqrt(2 |dxyz| + |dxyz|^2)``, unbounded in slope near ``w = 0``;
    the decoded vector may miss unit length by as much, so the chord after normalising doubles."""
    dxyz = math.sqrt(3.0) * component_error
    dw = math.sqrt(2.0 * dxyz + dxyz * dxyz)
    chord = 2.0 * math.hypot(dxyz, dw)
    return math.degrees(4.0 * math.asin(min(1.0, chord / 2.0)))


def clip_excess(values: np.ndarray, lo: float, hi: float) -> float:
    """Largest distance of ``values`` outside ``[lo, hi]`` (0 when all lie inside)."""
    v = np.asarray(values, np.float64)
    if v.size == 0:
        return 0.0
    return float(max(0.0, lo - v.min(), v.max() - hi))


def colour_from_dc(dc_step: float) -> float:
    """Colour error (0-1 units) of an f_dc error ``dc_step``."""
    return SH_C0 * dc_step


def check_linear_scales(scene, path, format_name: str) -> None:
    """Refuse, in one line naming the first row, a scene with a scale that a format storing
    linear float32 scales (.splat, glTF) would store as 0 or inf, a file no reader takes back."""
    for start in range(0, scene.count, 1 << 16):  # the float32 scales, a block at a time
        scales = scene.activated_rows(start, start + (1 << 16)).scales
        bad = ~((scales > 0) & np.isfinite(scales)).all(axis=1)
        if bad.any():
            row = start + int(np.flatnonzero(bad)[0])
            logs = scene.log_scales[row]
            worst = float(logs[np.argmax(np.abs(logs))])
            raise SceneFormatError(path, f"row {row}: log-scale {worst:g} is beyond what the "
                                         f"{format_name} format's linear float32 scales hold "
                                         "(e^-103 to e^88); write .ply, which stores log-scales",
                                   "scale")


def relative_scale(log_step: float) -> float:
    """Relative scale error of a log-scale error ``log_step`` (inf beyond float64's range: a
    log-scale clipped by hundreds)."""
    return math.expm1(log_step) if log_step < 709.0 else math.inf


def position_slack(means: np.ndarray) -> float:
    """float32 rounding allowance of decoded positions (world units, Euclidean)."""
    m = np.abs(np.asarray(means, np.float64))
    return float(math.sqrt(3.0) * F32_SLACK * (m.max() if m.size else 0.0))


def codebook_1d(values: np.ndarray, size: int = SOG_CODEBOOK_SIZE,
                iterations: int = SOG_CODEBOOK_ITERATIONS) -> np.ndarray:
    """A sorted float64 codebook of at most ``size`` entries for the pooled ``values`` (1D k-means).

    Starts at the quantiles, runs Lloyd iterations on the sorted values, and pins the first and
    last entries to the data's min and max, so every value lies within half the largest gap
    between neighbouring entries of its nearest entry (the bound :func:`codebook_bound` gives).
    """
    v = np.sort(np.asarray(values, np.float64).ravel())
    if v.size == 0:
        return np.zeros(1)
    uniq = np.unique(v)
    if uniq.size <= size:
        return uniq
    # Blend quantiles with a uniform grid so sparse tails keep entries (bounds the largest gap).
    q = np.quantile(v, np.linspace(0.0, 1.0, size))
    u = np.linspace(v[0], v[-1], size)
    c = np.sort(0.5 * (q + u))
    csum = np.concatenate([[0.0], np.cumsum(v)])
    for _ in range(iterations):
        edges = 0.5 * (c[1:] + c[:-1])
        cut = np.concatenate([[0], np.searchsorted(v, edges), [v.size]])
        counts = np.diff(cut)
        sums = csum[cut[1:]] - csum[cut[:-1]]
        c = np.where(counts > 0, sums / np.maximum(counts, 1), c)
        c = np.sort(c)
    c[0], c[-1] = v[0], v[-1]
    return np.sort(c)


def codebook_labels(values: np.ndarray, codebook: np.ndarray) -> np.ndarray:
    """uint8 index of the nearest ``codebook`` entry (sorted) for each value (same shape)."""
    v = np.asarray(values, np.float64)
    codebook = np.asarray(codebook, np.float64)  # a float32 book's extremes would overflow
    edges = 0.5 * (codebook[1:] + codebook[:-1])
    return np.searchsorted(edges, v).astype(np.uint8)


def codebook_bound(codebook: np.ndarray, values: np.ndarray) -> float:
    """Bound on ``|value - nearest entry|``: half the largest gap between neighbouring entries,
    or the distance outside the codebook's span for values beyond it (float32 codebooks)."""
    c = np.asarray(codebook, np.float64)
    half_gap = 0.5 * float(np.diff(c).max()) if c.size > 1 else 0.0
    return max(half_gap, clip_excess(values, c[0], c[-1])) * (1.0 + 1e-6)
