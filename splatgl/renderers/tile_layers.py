"""The tile renderer's layers beyond colour and depth (splatgl/output/layers.py), and geometry
under the splats: which switches its stages get, which buffers they write, and the readback.

Each layer is a switch of its own (shaders/tile_rasterize.comp): NORMAL_OUTPUT (the project
stage writes each splat's normal, the rasterizer accumulates ``N = sum n w``), ORDERED_OUTPUT
(median depth, count, top contributor: the per-pixel loop already runs front to back with the
reference's stop, so they are exact up to float rounding) and UNDER (a splat at or behind the
geometry's depth is skipped; the colour is composited over the geometry on the CPU).
"""

from __future__ import annotations

import numpy as np

from ..gl.buffers import GrowableBuffer
from ..errors import SplatglError
from ..output.layers import ORDERED, Layer, RenderOutput
from ..output.under import UnderLayer, composite_depth, composite_under


def layer_switches(layers: frozenset[Layer], under: UnderLayer | None,
                   per_pixel: bool = False) -> dict[str, object]:
    """The ``#define`` switches of the project and rasterize stages for ``layers``; refused
    (one line) with the per-pixel order, which draws colour, alpha and depth only."""
    d: dict[str, object] = {}
    if Layer.NORMAL in layers:
        d["NORMAL_OUTPUT"] = 1
    if layers & ORDERED:
        d["ORDERED_OUTPUT"] = 1
    if under is not None:
        d["UNDER"] = 1
    if d and per_pixel:
        raise SplatglError("--order per-pixel draws colour, alpha and depth only: it cannot be "
                           "combined with --under or the normal, median-depth, count and top-id "
                           "layers yet")
    return d


def size_layer_buffers(bufs: dict[str, GrowableBuffer], switches: dict[str, object],
                       splats: int, pixels: int, under: UnderLayer | None) -> None:
    """Grow the buffers the switches write (and upload the geometry depth)."""
    if "NORMAL_OUTPUT" in switches:
        bufs["NORMAL"].ensure(splats * 16)
        bufs["OUT_NORMAL"].ensure(pixels * 16)
    if "ORDERED_OUTPUT" in switches:
        bufs["OUT_ORDERED_F"].ensure(pixels * 8)
        bufs["OUT_ORDERED_U"].ensure(pixels * 8)
    if under is not None:
        bufs["UNDER"].upload(np.ascontiguousarray(under.depth, np.float32).tobytes())


def layer_output(bufs: dict[str, GrowableBuffer], rgba: np.ndarray, depth: np.ndarray | None,
                 layers: frozenset[Layer], under: UnderLayer | None, background) -> RenderOutput:
    """The frame's :class:`RenderOutput` from the rasterizer's buffers (``rgba``: its output,
    background 0 when ``under`` is given; ``depth``: (H, W) or None)."""
    h, w = rgba.shape[:2]
    planes: dict[str, np.ndarray] = {}
    if Layer.NORMAL in layers:
        planes["normal"] = bufs["OUT_NORMAL"].read(h * w * 16, np.float32).reshape(h, w, 4)[..., :3].copy()
    if layers & ORDERED:
        f = bufs["OUT_ORDERED_F"].read(h * w * 8, np.float32).reshape(h, w, 2)
        u = bufs["OUT_ORDERED_U"].read(h * w * 8, np.uint32).reshape(h, w, 2)
        if Layer.MEDIAN_DEPTH in layers:
            planes["median_depth"] = f[..., 0].copy()
        if Layer.COUNT in layers:
            planes["count"] = u[..., 0].copy()
        if Layer.TOP_ID in layers:
            planes["top_id"] = u[..., 1].astype(np.int64) - 1
    if under is not None:
        if depth is not None:
            depth = composite_depth(depth, rgba[..., 3], under)
        rgba = composite_under(rgba[..., :3], rgba[..., 3], under, background)
    if depth is None:
        depth = np.zeros((0, 0), np.float32)
    return RenderOutput(rgba.copy(), depth.copy(), layers, **planes)
