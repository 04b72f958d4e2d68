"""Pictures for people: error heat maps, side-by-side renders, colourised depth, with scale bars."""

from __future__ import annotations

import numpy as np
import OpenImageIO as oiio

#: Colour map of the heat map: black -> purple -> orange -> yellow -> white (perceptually ordered).
_STOPS = np.array([
    [0.0, 0.0, 0.0], [0.33, 0.06, 0.45], [0.85, 0.25, 0.25], [0.99, 0.65, 0.05], [1.0, 1.0, 0.9],
])


def colormap(t: np.ndarray) -> np.ndarray:
    """Map values in [0, 1] (any shape) to RGB (shape + (3,)), clipping outside."""
    t = np.clip(np.asarray(t, np.float64), 0.0, 1.0) * (len(_STOPS) - 1)
    i = np.minimum(t.astype(int), len(_STOPS) - 2)
    f = (t - i)[..., None]
    return (_STOPS[i] * (1 - f) + _STOPS[i + 1] * f).astype(np.float32)


def _label(img: np.ndarray, x: int, y: int, text: str, size: int = 14) -> np.ndarray:
    """Draw ``text`` into an (H, W, 3) float image with OpenImageIO's built-in font."""
    h, w = img.shape[:2]
    buf = oiio.ImageBuf(oiio.ImageSpec(w, h, 3, oiio.FLOAT))
    buf.set_pixels(oiio.ROI(0, w, 0, h, 0, 1, 0, 3), np.ascontiguousarray(img, np.float32))
    oiio.ImageBufAlgo.render_text(buf, x, y, text, size, "", (1.0, 1.0, 1.0))
    return np.asarray(buf.get_pixels(oiio.FLOAT), np.float32).reshape(h, w, 3)


def _with_scale_bar(img: np.ndarray, low: str, high: str) -> np.ndarray:
    """Append a colour ramp with ``low`` / ``high`` labels under an (H, W, 3) image -> RGBA."""
    w = img.shape[1]
    bar = np.zeros((34, w, 3), np.float32)
    bar[2:14] = colormap(np.linspace(0.0, 1.0, w))[None]
    if w >= 120:
        bar = _label(bar, 2, 30, low)
        bar = _label(bar, max(2, w - 7 * len(high) - 2), 30, high)
    out = np.concatenate([img, bar], axis=0)
    return np.concatenate([out, np.ones(out.shape[:2] + (1,), np.float32)], -1)


def heatmap(got: np.ndarray, expected: np.ndarray, scale: float) -> np.ndarray:
    """(H + bar, W, 4) image: per-pixel max channel |error| / scale through :func:`colormap`,
    with a labelled colour scale bar (0 .. scale) underneath."""
    err = np.abs(got[..., :3].astype(np.float64) - expected[..., :3]).max(axis=-1)
    return _with_scale_bar(colormap(err / scale), "0", f"{scale:.3g} ({scale * 255:.3g}/255) and above")


def depth_preview(expected_depth: np.ndarray, alpha: np.ndarray, min_alpha: float = 1e-3) -> np.ndarray:
    """(H + bar, W, 4) colourised expected depth (near = dark, far = bright), black where
    ``alpha < min_alpha``, with the depth range (world units) on a scale bar."""
    ok = alpha >= min_alpha
    if ok.any():
        lo, hi = np.percentile(expected_depth[ok], [1.0, 99.0])
    else:
        lo, hi = 0.0, 1.0
    hi = hi if hi > lo else lo + 1.0
    img = colormap((expected_depth - lo) / (hi - lo)) * ok[..., None]
    return _with_scale_bar(img.astype(np.float32), f"z {lo:.4g}", f"z {hi:.4g}")


def _caption(img: np.ndarray, text: str) -> np.ndarray:
    """Append a caption bar with ``text`` under an (H, W, 3) image -> RGBA."""
    w = img.shape[1]
    bar = np.zeros((20, w, 3), np.float32)
    if w >= 60:
        bar = _label(bar, 2, 15, text[: max(1, (w - 4) // 7)])
    out = np.concatenate([img, bar], axis=0)
    return np.concatenate([out, np.ones(out.shape[:2] + (1,), np.float32)], -1)


def value_preview(values: np.ndarray, mask: np.ndarray, name: str, integer: bool = False,
                  top: float | None = None) -> np.ndarray:
    """(H + bar, W, 4) ``values`` from 0 to ``top`` (default their largest where ``mask``)
    through :func:`colormap`, black outside ``mask``, with the range on a scale bar labelled
    ``name``."""
    if top is None:
        top = float(values[mask].max()) if mask.any() else 1.0
    top = top if top > 0 else 1.0
    img = colormap(values / top) * mask[..., None]
    high = f"{name} {int(top)}" if integer else f"{name} {top:.4g}"
    return _with_scale_bar(img.astype(np.float32), f"{name} 0", high)


def normal_preview(unit_normals: np.ndarray, mask: np.ndarray, space: str) -> np.ndarray:
    """(H + bar, W, 4) unit normals as colours ``(n + 1) / 2`` (black outside ``mask``), with
    the mapping and the ``space`` on a caption bar."""
    img = (0.5 * (unit_normals + 1.0)) * mask[..., None]
    return _caption(img.astype(np.float32), f"normal, {space}: (n+1)/2")


def id_preview(ids: np.ndarray) -> np.ndarray:
    """(H + bar, W, 4) a colour per splat index (a hash; black where ``ids < 0``), with the
    number of distinct indices on a caption bar."""
    x = ids.astype(np.uint64) * np.uint64(2654435761) & np.uint64(0xFFFFFF)
    rgb = np.stack([(x >> np.uint64(16)) & np.uint64(255), (x >> np.uint64(8)) & np.uint64(255),
                    x & np.uint64(255)], -1).astype(np.float32) / 255.0
    img = 0.25 + 0.75 * rgb
    img = np.where((ids >= 0)[..., None], img, 0.0)
    n = int(np.unique(ids[ids >= 0]).size)
    return _caption(img.astype(np.float32), f"top-id: {n} splats")


def side_by_side(left: np.ndarray, right: np.ndarray, names: tuple[str, str]) -> np.ndarray:
    """(H, 2W + 4, 4) image of two renders with their names written on them."""
    h = left.shape[0]
    gap = np.full((h, 4, 3), 0.5, np.float32)
    row = np.concatenate([np.clip(left[..., :3], 0, 1), gap, np.clip(right[..., :3], 0, 1)], axis=1)
    if h >= 24:
        row = _label(row, 4, 16, names[0])
        row = _label(row, left.shape[1] + 8, 16, names[1])
    return np.concatenate([row, np.ones((h, row.shape[1], 1), np.float32)], -1)
