"""k-means of SH coefficient vectors: the palette SOG stores for SH degrees 1-3.

Lloyd's algorithm with k-means++-style seeding replaced by a deterministic strided pick of the
rows (the scenes are large and the seeds are refined anyway), nearest-centroid assignment by
blocks through ``|x|^2 - 2 x.c + |c|^2`` (one matrix product per block, float32), and empty
clusters re-seeded from the rows farthest from their centroid.  Deterministic for a given input.
"""

from __future__ import annotations

import numpy as np

#: Rows per assignment block (keeps the block's distance matrix near 64 MiB at 4096 centroids).
BLOCK_BYTES = 64 << 20


#: Above this magnitude the squared distances could overflow float32: they are taken in float64.
FLOAT32_SAFE = 1e18


def assign(x: np.ndarray, centroids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(labels (N,) int64, squared distances (N,) float32) of each row of ``x`` (N, D) to its
    nearest row of ``centroids`` (K, D); float32 math unless values beyond
    :data:`FLOAT32_SAFE` need float64 (no overflow, no NumPy warning)."""
    big = x.size and float(np.abs(x).max()) > FLOAT32_SAFE
    work = np.float64 if big else np.float32
    c = centroids.astype(work)
    cc = (c * c).sum(axis=1)
    n = x.shape[0]
    rows = max(1, BLOCK_BYTES // (4 * max(1, c.shape[0])))
    labels = np.empty(n, np.int64)
    dist = np.empty(n, np.float32)
    for start in range(0, n, rows):
        xb = x[start:start + rows].astype(work)
        d = cc[None, :] - 2.0 * (xb @ c.T)
        lab = np.argmin(d, axis=1)
        labels[start:start + rows] = lab
        near = np.maximum(0.0, d[np.arange(len(lab)), lab] + (xb * xb).sum(axis=1))
        with np.errstate(over="ignore"):  # a float64 distance beyond float32: inf, still largest
            dist[start:start + rows] = near
    return labels, dist


def kmeans(x: np.ndarray, k: int, iterations: int) -> tuple[np.ndarray, np.ndarray]:
    """``(centroids (K', D) float32, labels (N,) int64)`` of the rows of ``x`` (N, D), K' =
    min(k, N).  Each iteration assigns every row, then moves each centroid to its rows' mean."""
    x = np.ascontiguousarray(x, np.float32)
    n = x.shape[0]
    k = max(1, min(k, n))
    order = np.argsort(x.sum(axis=1, dtype=np.float64), kind="stable")
    centroids = x[order[np.linspace(0, n - 1, k).astype(np.int64)]].copy()
    labels = np.zeros(n, np.int64)
    for _ in range(max(1, iterations)):
        labels, dist = assign(x, centroids)
        counts = np.bincount(labels, minlength=k)
        sums = np.stack([np.bincount(labels, weights=x[:, d], minlength=k)
                         for d in range(x.shape[1])], axis=1)
        filled = counts > 0
        centroids[filled] = (sums[filled] / counts[filled, None]).astype(np.float32)
        empty = np.flatnonzero(~filled)
        if empty.size:  # re-seed from the worst-fitted rows
            far = np.argsort(dist)[::-1][: empty.size]
            centroids[empty[: far.size]] = x[far]
    labels, _ = assign(x, centroids)
    return centroids, labels
