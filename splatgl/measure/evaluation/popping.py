"""Popping: temporal inconsistency along a camera path that the camera's motion does not explain.

For consecutive frames k and k+1 (colour, expected depth ``D / A`` and alpha, with their cameras),
frame k is warped into frame k+1: each pixel of k+1 with ``A >= SOLID_ALPHA`` is lifted to the
world with its depth and k+1's camera, projected into frame k, and frame k is sampled there
(bilinear).  The pixel is masked (not scored) where that lands outside frame k or on a pixel of
k that is not solid, where frame k's depth there differs from the point's depth in k's camera
by more than DEPTH_TOLERANCE (a disocclusion: the point was hidden in frame k), or where frame
k's depth varies by more than DEPTH_TOLERANCE across the sample's 2x2 footprint (a silhouette,
whose blended depth belongs to no surface).  The error of each kept pixel is then measured
between frame k+1 and warped frame k (masked pixels are set equal in both, so that a metric's
filters do not carry their difference into kept pixels):

- ``flip`` (default when ``flip-evaluator`` is installed, ``pip install 'splatgl[fidelity]'``):
  NVIDIA's FLIP (Andersson et al. 2020), LDR, 67 pixels per degree, colours clipped to [0, 1];
- ``own`` (the fallback): the smallest of the largest channel difference between the pixel of
  frame k+1 and the 3x3 neighbourhood of its warped sample, so that a warp off by up to a pixel
  (edges, resampling) costs nothing and what remains is a change of colour, which is what a
  splat popping in front of another makes.

Per frame pair: ``score`` = mean error over the kept pixels, ``popped`` = share of the kept pixels
whose error exceeds the metric's POP_THRESHOLD, ``coherent`` = share of the kept pixels popped
together with their 8 neighbours (a region at least 3x3 pixels changed: what a splat jumping in
front of another does, while pixel-scale flicker, speckle from resampling or from orders that
differ pixel by pixel, does not count), ``kept`` = share of the image scored.  A
perspective or orthographic camera; the depth must be the expected depth of the same render.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from ...cameras.camera import Camera
from ...cameras.orthographic import Orthographic
from ...cameras.pinhole import Pinhole
from ...errors import SplatglError

#: Pixels with at least this alpha carry a surface (and a depth) to warp.
SOLID_ALPHA = 0.5
#: Relative depth difference beyond which a warped pixel is a disocclusion or a silhouette.
DEPTH_TOLERANCE = 0.02
#: Error above which a kept pixel counts as popped, per metric (FLIP: a difference an observer
#: notices at a glance; own: 13/255 in the largest channel).
POP_THRESHOLD = {"flip": 0.1, "own": 0.05}
#: The metrics :func:`popping` computes.
METRICS = ("flip", "own")


def flip_available() -> bool:
    try:
        import flip_evaluator  # noqa: F401
    except ImportError:
        return False
    return True


def default_metric() -> str:
    """``flip`` where flip-evaluator is installed, else ``own``."""
    return "flip" if flip_available() else "own"


@dataclass(frozen=True)
class Frame:
    """One rendered frame: rgb (H, W, 3) composited colour, depth (H, W) expected depth ``D / A``
    (view z, world units), alpha (H, W), and the camera it was rendered from."""

    rgb: np.ndarray
    depth: np.ndarray
    alpha: np.ndarray
    camera: Camera


@dataclass(frozen=True)
class PairScore:
    """Popping between frame ``index - 1`` and ``index`` (module doc)."""

    index: int
    score: float
    popped: float
    kept: float
    coherent: float = 0.0

    def as_dict(self) -> dict:
        return asdict(self)


def check_camera(camera: Camera) -> None:
    if not isinstance(camera.model, (Pinhole, Orthographic)):
        raise SplatglError(f"the popping metric warps perspective and orthographic frames, not "
                           f"{camera.model.name}")


def _rays(camera: Camera, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
    """(x, y) of the rays through image points (u, v): per unit depth (perspective) or offsets."""
    check_camera(camera)
    return (u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, isinstance(camera.model, Orthographic)


def _bilinear(img: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``img`` (H, W, ...) at pixel-index coordinates (x, y) (centre of pixel j at j), clamped."""
    h, w = img.shape[:2]
    x0 = np.clip(np.floor(x).astype(np.int64), 0, w - 2)
    y0 = np.clip(np.floor(y).astype(np.int64), 0, h - 2)
    fx = np.clip(x - x0, 0.0, 1.0)
    fy = np.clip(y - y0, 0.0, 1.0)
    if img.ndim == 3:
        fx, fy = fx[..., None], fy[..., None]
    return ((img[y0, x0] * (1 - fx) + img[y0, x0 + 1] * fx) * (1 - fy)
            + (img[y0 + 1, x0] * (1 - fx) + img[y0 + 1, x0 + 1] * fx) * fy)


def warp(prev: Frame, cur: Frame) -> tuple[np.ndarray, np.ndarray]:
    """Frame ``prev`` warped into ``cur``'s view: ((H, W, 3) colour, (H, W) bool kept)."""
    h, w = cur.depth.shape
    j, i = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    z = cur.depth.astype(np.float64)
    rx, ry, parallel = _rays(cur.camera, j + 0.5, i + 0.5)
    p_cam = np.stack([rx, ry, np.ones_like(rx)], -1) * z[..., None] if not parallel else \
        np.stack([rx, ry, z], -1)
    world = (p_cam - cur.camera.translation) @ cur.camera.rotation      # R^T (p - t)
    q = world @ prev.camera.rotation.T + prev.camera.translation
    qz = q[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        if isinstance(prev.camera.model, Orthographic):
            u, v = prev.camera.fx * q[..., 0] + prev.camera.cx, prev.camera.fy * q[..., 1] + prev.camera.cy
        else:
            u = prev.camera.fx * q[..., 0] / qz + prev.camera.cx
            v = prev.camera.fy * q[..., 1] / qz + prev.camera.cy
    check_camera(prev.camera)
    x, y = u - 0.5, v - 0.5                                           # pixel-index coordinates
    kept = ((cur.alpha >= SOLID_ALPHA) & (z > 0) & (qz > 0) & np.isfinite(x) & np.isfinite(y)
            & (x >= 0) & (x <= w - 1) & (y >= 0) & (y <= h - 1))
    x, y = np.where(kept, x, 0.0), np.where(kept, y, 0.0)
    x0 = np.clip(np.floor(x).astype(np.int64), 0, w - 2)
    y0 = np.clip(np.floor(y).astype(np.int64), 0, h - 2)
    corners = np.stack([prev.depth[y0, x0], prev.depth[y0, x0 + 1], prev.depth[y0 + 1, x0],
                        prev.depth[y0 + 1, x0 + 1]], -1).astype(np.float64)
    solid = np.stack([prev.alpha[y0, x0], prev.alpha[y0, x0 + 1], prev.alpha[y0 + 1, x0],
                      prev.alpha[y0 + 1, x0 + 1]], -1) >= SOLID_ALPHA
    tol = DEPTH_TOLERANCE * np.maximum(qz, 1e-30)
    kept &= solid.all(-1) & (corners.max(-1) - corners.min(-1) <= tol)
    kept &= np.abs(_bilinear(prev.depth.astype(np.float64), x, y) - qz) <= tol
    warped = _bilinear(prev.rgb.astype(np.float64), x, y)
    return np.where(kept[..., None], warped, cur.rgb), kept


def _own_error(cur: np.ndarray, warped: np.ndarray) -> np.ndarray:
    """Smallest largest-channel difference over the warped 3x3 neighbourhood, (H, W)."""
    h, w = cur.shape[:2]
    pad = np.pad(warped, ((1, 1), (1, 1), (0, 0)), mode="edge")
    best = np.full((h, w), np.inf)
    for dy in range(3):
        for dx in range(3):
            best = np.minimum(best, np.abs(cur - pad[dy:dy + h, dx:dx + w]).max(-1))
    return best


def error_map(cur: np.ndarray, warped: np.ndarray, metric: str) -> np.ndarray:
    """(H, W) per-pixel error of ``metric`` between frame k+1 and warped frame k."""
    if metric == "own":
        return _own_error(cur, warped)
    if metric != "flip":
        raise SplatglError(f"popping metric must be one of {', '.join(METRICS)}, got {metric!r}")
    try:
        import flip_evaluator
    except ImportError:
        raise SplatglError("the popping metric 'flip' needs flip-evaluator (pip install "
                           "'splatgl[fidelity]'); the fallback is --popping-metric own") from None
    ref = np.ascontiguousarray(np.clip(cur, 0, 1), np.float32)
    test = np.ascontiguousarray(np.clip(warped, 0, 1), np.float32)
    err = flip_evaluator.evaluate(ref, test, "LDR", applyMagma=False, computeMeanError=False)[0]
    return np.asarray(err, np.float64).reshape(ref.shape[:2] + (-1,))[..., 0]


def score_pair(prev: Frame, cur: Frame, index: int, metric: str) -> tuple[PairScore, np.ndarray]:
    """Popping between ``prev`` and ``cur`` (frame ``index``), and its (H, W) error map (0 where
    masked)."""
    warped, kept = warp(prev, cur)
    err = np.where(kept, error_map(cur.rgb.astype(np.float64), warped, metric), 0.0)
    n = int(kept.sum())
    score = float(err[kept].mean()) if n else 0.0
    hot = kept & (err > POP_THRESHOLD[metric])
    popped = float(hot.sum() / n) if n else 0.0
    coherent = float((_eroded(hot) & kept).sum() / n) if n else 0.0
    return PairScore(index, score, popped, n / kept.size, coherent), err


def _eroded(mask: np.ndarray) -> np.ndarray:
    """Pixels of ``mask`` whose 8 neighbours are in it too (a 3x3 erosion; borders out)."""
    h, w = mask.shape
    pad = np.pad(mask, 1, constant_values=False)
    out = np.ones((h, w), bool)
    for dy in range(3):
        for dx in range(3):
            out &= pad[dy:dy + h, dx:dx + w]
    return out


def popping(frames: list[Frame], metric: str | None = None) -> list[PairScore]:
    """:class:`PairScore` of every pair of consecutive ``frames`` (module doc)."""
    metric = metric or default_metric()
    return [score_pair(frames[k - 1], frames[k], k, metric)[0] for k in range(1, len(frames))]


def distribution(scores: list[PairScore]) -> dict[str, float]:
    """Median, 90th percentile and largest per-pair score and popped share."""
    if not scores:
        return {}
    s = np.array([p.score for p in scores])
    q = np.array([p.popped for p in scores])
    c = np.array([p.coherent for p in scores])
    return {"score_median": float(np.median(s)), "score_p90": float(np.percentile(s, 90)),
            "score_max": float(s.max()), "popped_median": float(np.median(q)),
            "popped_p90": float(np.percentile(q, 90)), "popped_max": float(q.max()),
            "coherent_median": float(np.median(c)), "coherent_max": float(c.max()),
            "kept_mean": float(np.mean([p.kept for p in scores])), "pairs": len(scores)}


