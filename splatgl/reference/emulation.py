"""How the reference applies the emulation knobs (:mod:`splatgl.scene.emulation`).

Each knob touches one stage; the stages call these helpers only when the knob differs from
the reference's own rule, so with the default :class:`Emulation` nothing here runs:

- ``half``, ``sh``, ``compensation``, ``low_pass``: the scene arrays and the projection
  (:func:`scene_arrays`, :func:`projection_settings`);
- ``extent``: each splat's support on screen (:func:`support`): a per-pixel clip (a largest
  ``q = -2 power``, and/or a box ``max_i |rows_i . d| <= 1`` in pixels) and the tile rectangle
  covering it (:func:`splatgl.reference.stages.box_rect`, exact about which pixels a box holds);
- ``sort`` and ``depth``: the low 32 bits of the sort keys (:func:`key_bits`);
- ``min_alpha`` and ``alpha_max``: the alpha rule in rasterize (through
  :class:`~splatgl.reference.options.ReferenceOptions`), with :func:`clip_alpha` for the clip.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ..constants import FAST_CORNER_SIGMAS
from ..scene.emulation import Emulation
from ..scene.settings import GpuStorage, QuadExtent, RenderSettings, SortKey
from ..order.sort import bucket_keys
from ..splatmath import project as pm

#: ``extent=fixed``: the ellipse out to sqrt(8) sigma, as ``q = d^T Q d <= FIXED_Q``.
FIXED_Q = FAST_CORNER_SIGMAS ** 2


def scene_arrays(means: np.ndarray, scales: np.ndarray, emulation: Emulation
                 ) -> tuple[np.ndarray, np.ndarray]:
    """``half=on``: (N, 3) world means and (N, 3) activated scales rounded to float16 (and back
    to float64); values beyond float16's range become inf and the splat is culled as
    non-finite.  Otherwise unchanged."""
    if not emulation.half:
        return means, scales
    with np.errstate(over="ignore"):
        return (np.asarray(means, np.float64).astype(np.float16).astype(np.float64),
                np.asarray(scales, np.float64).astype(np.float16).astype(np.float64))


def projection_settings(settings: RenderSettings, emulation: Emulation) -> RenderSettings:
    """``settings`` with the ``sh`` and ``compensation`` knobs applied (when set)."""
    changes = {}
    if emulation.sh is not None:
        changes["sh_degree"] = emulation.sh
    if emulation.compensation is not None:
        changes["antialias"] = emulation.compensation
    return dataclasses.replace(settings, **changes) if changes else settings


@dataclass(frozen=True)
class Support:
    """A splat's support on screen under an ``extent`` knob (N rows).

    clip_q: (N,) largest ``q = d^T Q d`` drawn (inf: no limit), or None.
    clip_rows: (N, 2, 2) rows r_i in 1/px: a pixel at offset d from the centre is drawn only
        where ``|r_0 . d| <= 1`` and ``|r_1 . d| <= 1``, or None.
    half: (N, 2) half extents (x, y) in pixels of a box holding the support.
    """

    clip_q: np.ndarray | None
    clip_rows: np.ndarray | None
    half: np.ndarray


def _eigen(cov2d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Eigenvalues (lam1 >= lam2) and unit eigenvectors of (N, 2, 2) covariances, float64."""
    c = cov2d.astype(np.float64)
    lam, vec = np.linalg.eigh(np.nan_to_num(c))
    return lam[:, 1], np.maximum(lam[:, 0], 0.0), vec[:, :, 1], vec[:, :, 0]


def support(extent: str, cov2d: np.ndarray, opacity: np.ndarray, min_alpha: float) -> Support:
    """The support of each splat for an ``extent`` knob other than ``tiles`` (the module doc
    of :mod:`splatgl.scene.emulation` defines them); (N, 2, 2) dilated covariances (px^2),
    (N,) opacities."""
    dt = cov2d.dtype
    sxx = np.maximum(cov2d[:, 0, 0].astype(np.float64), 0.0)
    syy = np.maximum(cov2d[:, 1, 1].astype(np.float64), 0.0)
    diag = np.stack([np.sqrt(sxx), np.sqrt(syy)], -1)    # 1-sigma half extents of the ellipse box
    if extent == "fixed":
        half = math.sqrt(FIXED_Q) * diag
        return Support(np.full(len(cov2d), FIXED_Q, dt), None, half)
    if extent == "opacity":
        with np.errstate(divide="ignore", invalid="ignore"):
            q = np.maximum(2.0 * np.log(np.maximum(opacity.astype(np.float64), 1e-30) / min_alpha), 0.0)
        return Support(None, None, np.sqrt(q)[:, None] * diag)
    if extent == "square":
        r = pm.reference_radius(cov2d).astype(np.float64)
        rows = np.zeros((len(cov2d), 2, 2))
        with np.errstate(divide="ignore"):
            inv = np.where(r > 0, 1.0 / np.where(r > 0, r, 1.0), np.inf)
        rows[:, 0, 0] = rows[:, 1, 1] = inv
        return Support(None, rows.astype(dt), np.stack([r, r], -1))
    if extent == "fixed-quad":
        lam1, lam2, v1, v2 = _eigen(cov2d)
        k = FAST_CORNER_SIGMAS
        a1 = v1 * (k * np.sqrt(lam1))[:, None]          # half-axes of the quad, pixels
        a2 = v2 * (k * np.sqrt(lam2))[:, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            r1 = v1 / np.where(lam1 > 0, k * np.sqrt(lam1), np.inf)[:, None]
            r2 = v2 / np.where(lam2 > 0, k * np.sqrt(lam2), np.inf)[:, None]
        rows = np.nan_to_num(np.stack([r1, r2], 1), posinf=0.0)
        return Support(None, rows.astype(dt), np.abs(a1) + np.abs(a2))
    raise ValueError(f"extent {extent!r} has no support rule here (tiles is the reference's own)")


def clip_mask(power: np.ndarray, dx: np.ndarray, dy: np.ndarray,
              clip_q: np.ndarray | None, clip_rows: np.ndarray | None) -> np.ndarray:
    """Where each splat's support (:class:`Support`) holds the pixel: (n, K, 16, 16) bool.

    ``power``: (n, K, 16, 16) by (row, column); ``dx`` (n, K, 16) by column, ``dy`` (n, K, 16)
    by row; ``clip_q`` (n, K) and ``clip_rows`` (n, K, 2, 2) gathered per tile, or None."""
    dt = power.dtype.type
    keep = np.ones(power.shape, bool)
    if clip_q is not None:
        keep &= dt(-2.0) * power <= clip_q[:, :, None, None]
    if clip_rows is not None:
        for i in range(2):
            c = (clip_rows[:, :, i, 0, None, None] * dx[:, :, None, :]
                 + clip_rows[:, :, i, 1, None, None] * dy[:, :, :, None])
            keep &= np.abs(c) <= dt(1.0)
    return keep


def key_bits(emulation: Emulation, depth: np.ndarray, p_cam: np.ndarray, visible: np.ndarray
             ) -> np.ndarray | None:
    """The low 32 bits of each splat's sort key under the ``sort`` and ``depth`` knobs:
    float32 bits of view z or of the distance ``|p_cam|`` (``depth``), or the 16-bit bucket of
    that depth between the nearest and farthest visible splat (``sort=bucket16``).  None when
    both knobs are the reference's own (the keys then hold the float bits of ``depth``).
    (N,) sort depths, (N, 3) camera-space centres, (N,) visibility -> (N,) uint64 or None."""
    if emulation.sort == "exact" and emulation.depth == "auto":
        return None
    if emulation.depth == "z":
        depth = p_cam[:, 2]
    elif emulation.depth == "distance":
        depth = np.linalg.norm(p_cam.astype(np.float64), axis=1).astype(depth.dtype)
    if emulation.sort == "exact":
        return np.ascontiguousarray(depth, np.float32).view(np.uint32).astype(np.uint64)
    bits = np.zeros(len(depth), np.uint64)
    bits[visible] = bucket_keys(depth[visible])
    return bits


def quad_emulation(settings) -> Emulation:
    """The knobs that make the reference follow the quad path's variants in ``settings``
    (:class:`~splatgl.scene.settings.RenderSettings`): its sort keys, its quad extent, and
    float16 scales of compact GPU storage (as ``half=on``).  Blend precision and the missing
    early stop have no knob (the quad path's own differences, docs/results/summary.md)."""
    extent = {QuadExtent.ELLIPSE: "opacity", QuadExtent.SQUARE: "square",
              QuadExtent.FAST: "fixed-quad"}[settings.extent]
    return Emulation(sort="bucket16" if settings.sort_key is SortKey.BUCKET16 else "exact",
                     extent=extent, half=settings.gpu_storage is GpuStorage.COMPACT)
