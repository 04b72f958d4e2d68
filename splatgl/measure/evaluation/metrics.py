"""Image error metrics for comparing renderers: PSNR, SSIM, absolute errors, shares off."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from ...errors import SplatglError

#: Thresholds reported as "share of pixels off by more than": one and four 8-bit steps.
OFF_THRESHOLDS = (1.0 / 255.0, 4.0 / 255.0)


@dataclass(frozen=True)
class ImageErrors:
    """Errors of an RGB image against a reference, both (H, W, 3) in [0, 1]-ish units.

    ``psnr`` uses a peak of 1.0 (infinite for identical images); ``ssim`` is the mean SSIM
    over channels (Gaussian window, sigma 1.5, Wang et al. 2004 constants); ``off_1`` and
    ``off_4`` are the shares of pixels whose largest channel error exceeds 1/255 and 4/255.
    """

    psnr: float
    ssim: float
    mean_abs: float
    max_abs: float
    off_1: float
    off_4: float

    def as_dict(self) -> dict[str, float]:
        return {k: (None if isinstance(v, float) and math.isinf(v) else v) for k, v in asdict(self).items()}


def psnr(a: np.ndarray, b: np.ndarray, peak: float = 1.0) -> float:
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return math.inf if mse == 0.0 else 10.0 * math.log10(peak * peak / mse)


#: SSIM's Gaussian window is SSIM_WINDOW x SSIM_WINDOW pixels (Wang et al. 2004: 11, sigma 1.5).
SSIM_WINDOW = 11
SSIM_SIGMA = 1.5


def check_ssim_size(width: int, height: int, what: str) -> None:
    """Refuse an image smaller than SSIM's window (the 'valid' region would be empty)."""
    if width < SSIM_WINDOW or height < SSIM_WINDOW:
        raise SplatglError(f"{what} {width}x{height} is smaller than SSIM's {SSIM_WINDOW}x"
                           f"{SSIM_WINDOW} window; SSIM needs at least {SSIM_WINDOW} pixels a side")


def _gaussian_blur(img: np.ndarray, sigma: float = SSIM_SIGMA, radius: int = SSIM_WINDOW // 2) -> np.ndarray:
    """Separable Gaussian blur of (H, W) with an 11-tap window, 'valid' region only."""
    x = np.arange(-radius, radius + 1, dtype=np.float64)
    w = np.exp(-0.5 * (x / sigma) ** 2)
    w /= w.sum()
    h, wd = img.shape
    rows = sum(w[k] * img[:, k:wd - 2 * radius + k] for k in range(2 * radius + 1))
    return sum(w[k] * rows[k:h - 2 * radius + k, :] for k in range(2 * radius + 1))


def ssim(a: np.ndarray, b: np.ndarray, peak: float = 1.0) -> float:
    """Mean SSIM of two (H, W, C) images (per channel, averaged) over the 'valid' region.

    Raises:
        SplatglError: an image smaller than the 11 x 11 window (:func:`check_ssim_size`).
    """
    check_ssim_size(a.shape[1], a.shape[0], "image")
    c1, c2 = (0.01 * peak) ** 2, (0.03 * peak) ** 2
    values = []
    for ch in range(a.shape[-1]):
        x, y = a[..., ch].astype(np.float64), b[..., ch].astype(np.float64)
        mx, my = _gaussian_blur(x), _gaussian_blur(y)
        sxx = _gaussian_blur(x * x) - mx * mx
        syy = _gaussian_blur(y * y) - my * my
        sxy = _gaussian_blur(x * y) - mx * my
        s = ((2 * mx * my + c1) * (2 * sxy + c2)) / ((mx * mx + my * my + c1) * (sxx + syy + c2))
        values.append(float(s.mean()))
    return float(np.mean(values))


def image_errors(got: np.ndarray, expected: np.ndarray) -> ImageErrors:
    """All metrics of ``got`` against ``expected``, (H, W, >=3) arrays (RGB used)."""
    g, e = got[..., :3], expected[..., :3]
    diff = np.abs(g.astype(np.float64) - e.astype(np.float64))
    per_pixel = diff.max(axis=-1)
    return ImageErrors(
        psnr=psnr(g, e), ssim=ssim(g, e), mean_abs=float(diff.mean()), max_abs=float(diff.max()),
        off_1=float((per_pixel > OFF_THRESHOLDS[0]).mean()),
        off_4=float((per_pixel > OFF_THRESHOLDS[1]).mean()),
    )


def depth_errors(got, expected) -> dict[str, float]:
    """Alpha and accumulated-depth errors of two :class:`splatgl.output.layers.RenderOutput`.

    ``depth_max_rel`` is the largest ``|D_got - D_expected|`` over the farthest expected depth
    ``D / A`` of the reference (where A >= 0.5), so it reads in the depth's own units.
    """
    a = expected.alpha
    exp_depth = expected.expected_depth()
    solid = a >= 0.5
    scale = float(exp_depth[solid].max()) if solid.any() else float(max(exp_depth.max(), 1e-30))
    d = np.abs(got.depth.astype(np.float64) - expected.depth)
    return {
        "alpha_max_abs": float(np.abs(got.alpha.astype(np.float64) - a).max()),
        "depth_max_abs": float(d.max()),
        "depth_scale": scale,
        "depth_max_rel": float(d.max() / scale) if scale > 0 else 0.0,
    }


def layer_errors(got, expected, solid_alpha: float = 0.5) -> dict[str, float]:
    """How the further layers of two :class:`splatgl.output.layers.RenderOutput` differ
    (those both hold; docs/layers.md reports them against the reference).

    normal: the angle between the unit normals where both alphas are at least
    ``solid_alpha`` (degrees: median, 99th percentile, max) and the largest difference of the
    accumulated normals; median depth: the share of pixels blended by either whose median
    differs by more than 1e-4 relative, and the largest relative difference there; count: the
    share that differs and the largest difference; top-id: the share of pixels blended by
    either whose top contributor differs.
    """
    out: dict[str, float] = {}
    blended = (np.asarray(expected.alpha) > 0) | (np.asarray(got.alpha) > 0)
    if got.normal is not None and expected.normal is not None:
        solid = (got.alpha >= solid_alpha) & (expected.alpha >= solid_alpha)
        cos = (got.unit_normals() * expected.unit_normals()).sum(-1)[solid]
        angle = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))) if cos.size else np.zeros(1)
        out.update(normal_deg_median=float(np.median(angle)),
                   normal_deg_p99=float(np.percentile(angle, 99)), normal_deg_max=float(angle.max()),
                   normal_max_abs=float(np.abs(got.normal.astype(np.float64) - expected.normal).max()))
    if got.median_depth is not None and expected.median_depth is not None:
        g, e = got.median_depth.astype(np.float64), expected.median_depth.astype(np.float64)
        rel = np.abs(g - e) / np.maximum(np.abs(e), 1e-30)
        off = blended & (rel > 1e-4)
        out.update(median_off=float(off.sum() / max(blended.sum(), 1)),
                   median_max_rel=float(rel[blended].max()) if blended.any() else 0.0)
    if got.count is not None and expected.count is not None:
        d = np.abs(got.count.astype(np.int64) - expected.count.astype(np.int64))
        out.update(count_off=float((d > 0)[blended].mean()) if blended.any() else 0.0,
                   count_max_diff=float(d.max()))
    if got.top_id is not None and expected.top_id is not None:
        off = got.top_id != expected.top_id
        out.update(top_id_off=float(off[blended].mean()) if blended.any() else 0.0)
    return out
