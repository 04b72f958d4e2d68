"""The reference's layers beyond colour, alpha and depth, and its depth test against geometry.

:func:`splatgl.reference.rasterize.rasterize` blends each tile's splats in chunks; given a
:class:`RasterLayers`, it hands every chunk's alphas and weights to a :class:`BatchLayers`,
which keeps (per pixel of the batch's tiles):

- ``normal``: ``N = sum n w`` with ``w = alpha T`` the colour's weights;
- ``median_depth``: the ``z`` of the last splat blended while ``T > 0.5`` (``T`` before it:
  2DGS's ``if (T > 0.5) median_depth = depth``), 0 where none blended;
- ``top_id``: the scene row of the largest ``w`` (the first of equal ones: strictly larger
  weights replace it), -1 where none blended; ``top_weight`` that weight;

and, with ``under_depth``, drops every splat at or behind the geometry before it blends
(:meth:`BatchLayers.depth_test`: its ``z`` against the pixel's geometry depth in the same
metric).  The count layer is the rasterizer's own ``n_blended``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..constants import MEDIAN_T, TILE_SIZE


@dataclass(frozen=True)
class RasterLayers:
    """What :func:`~splatgl.reference.rasterize.rasterize` computes beyond colour and depth.

    Attributes:
        normals: (rows, 3) unit camera-space normals of the projected rows
            (:func:`splatgl.splatmath.normals.splat_normals`), or None (no normal layer).
        median: whether to keep the median depth.  top: whether to keep the top contributor.
        source: (rows,) int64 scene row of each projected row (an equirectangular seam copy
            names its original), or None (the identity).
        under_depth: (H, W) geometry depth in the splats' depth metric (+inf: none), or None.
    """

    normals: np.ndarray | None = None
    median: bool = False
    top: bool = False
    source: np.ndarray | None = None
    under_depth: np.ndarray | None = None

    def tiled_under(self, grid: tuple[int, int]) -> np.ndarray | None:
        """(tiles, 256) geometry depth per tile pixel (+inf outside the image), or None."""
        if self.under_depth is None:
            return None
        gw, gh = grid
        h, w = self.under_depth.shape
        full = np.full((gh * TILE_SIZE, gw * TILE_SIZE), np.inf, self.under_depth.dtype)
        full[:h, :w] = self.under_depth
        tiles = full.reshape(gh, TILE_SIZE, gw, TILE_SIZE).swapaxes(1, 2)
        return np.ascontiguousarray(tiles.reshape(gw * gh, TILE_SIZE * TILE_SIZE))

    def batch(self, n: int, dtype, under: np.ndarray | None) -> "BatchLayers":
        """The accumulators of a batch of ``n`` tiles (``under``: their (n, 256) rows of
        :meth:`tiled_under`)."""
        return BatchLayers(self, n, np.dtype(dtype), under)


class BatchLayers:
    """Per-pixel accumulators of one batch of tiles (module doc), compacted with the batch's
    working rows as tiles finish: ``out`` holds every tile of the batch, ``work`` those still
    blending."""

    def __init__(self, spec: RasterLayers, n: int, dtype: np.dtype, under: np.ndarray | None):
        self.spec = spec
        p = TILE_SIZE * TILE_SIZE
        self.out: dict[str, np.ndarray] = {}
        if spec.normals is not None:
            self.out["normal"] = np.zeros((n, p, 3), dtype)
        if spec.median:
            self.out["median_depth"] = np.zeros((n, p), dtype)
        if spec.top:
            self.out["top_weight"] = np.zeros((n, p), dtype)
            self.out["top_id"] = np.full((n, p), -1, np.int64)
        self.under = under

    def start(self, rows: np.ndarray) -> None:
        """Begin on the batch's busy tiles ``rows`` (indices into the batch)."""
        self.rows = rows
        self.work = {name: a[rows] for name, a in self.out.items()}
        self.work_under = self.under[rows] if self.under is not None else None

    def depth_test(self, alpha: np.ndarray, z: np.ndarray) -> np.ndarray:
        """(n, K, 256) ``alpha`` with 0 wherever ``z`` ((n, K, 1) per splat or (n, K, 256) per
        pixel) is at or behind the geometry."""
        if self.work_under is None:
            return alpha
        return np.where(z >= self.work_under[:, None, :], alpha.dtype.type(0.0), alpha)

    def add(self, sidx: np.ndarray, weights: np.ndarray, t_seq: np.ndarray, z: np.ndarray) -> None:
        """One chunk: ``sidx`` (n, K) projected rows, ``weights`` (n, K, 256) (0: not blended),
        ``t_seq`` (n, K + 1, 256) running T, ``z`` (n, K, 1) or (n, K, 256) splat depths."""
        w = self.work
        spec = self.spec
        if "normal" in w:
            w["normal"] += np.matmul(weights.transpose(0, 2, 1), spec.normals[sidx])
        k = weights.shape[1]
        if "median_depth" in w:
            before = (weights > 0) & (t_seq[:, :-1] > t_seq.dtype.type(MEDIAN_T))
            last = k - 1 - np.argmax(before[:, ::-1, :], axis=1)              # (n, 256)
            zz = np.broadcast_to(z, weights.shape)
            found = before.any(axis=1)
            picked = np.take_along_axis(zz, last[:, None, :], axis=1)[:, 0]
            w["median_depth"] = np.where(found, picked, w["median_depth"])
        if "top_id" in w:
            best = np.argmax(weights, axis=1)                                   # first maximum
            best_w = np.take_along_axis(weights, best[:, None, :], axis=1)[:, 0]
            better = best_w > w["top_weight"]
            rows = np.take_along_axis(sidx, best, axis=1)                        # (n, 256)
            ids = spec.source[rows] if spec.source is not None else rows
            w["top_weight"] = np.where(better, best_w, w["top_weight"])
            w["top_id"] = np.where(better, ids, w["top_id"])

    def retire(self, stop: np.ndarray, go: np.ndarray) -> None:
        """Tiles ``stop`` of the working rows are finished: store them, keep ``go``."""
        for name, a in self.work.items():
            self.out[name][self.rows[stop]] = a[stop]
            self.work[name] = a[go]
        if self.work_under is not None:
            self.work_under = self.work_under[go]
        self.rows = self.rows[go]
