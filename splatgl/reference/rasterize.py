"""Reference stage 5: ``rasterize``, per-tile front-to-back blending (3DGS's ``renderCUDA``).

For every pixel of a tile, the tile's depth-sorted splats are blended in order with

    power = -0.5 (a dx^2 + c dy^2) - b dx dy,   d = pixel centre - mean2d   (pixels)
    alpha = min(alpha_max, o exp(power)), skipped when power > 0 or alpha < 1/255
    (2DGS surfels: power = -0.5 min(u^2 + v^2, F |d|^2) from the ray-splat intersection,
    :func:`splatgl.splatmath.surfel.surfel_alpha`, d from the low-pass centre; z is the view z of the
    hit per pixel, or under GSPLAT the centre's view z)
    stop (without adding the splat) once T (1 - alpha) < 1e-4   (GSPLAT: <= 1e-4)
    C = sum c alpha T,  D = sum z alpha T,  A = 1 - T_final,  out = C + T_final background

Vectorisation: tiles are processed in batches; for a batch, the next ``chunk`` splats of every
tile are evaluated on all 256 pixels at once as (tiles, chunk, 256) arrays.  The transmittance
is a cumulative product seeded with the running T (the same sequence of float multiplications
as the serial loop), and since T never increases, the splats a pixel still blends form a prefix
of the chunk: those whose running product stays at or above 1e-4.  A tile leaves the batch when
its list is exhausted or all its pixels have stopped.  Batches run on a thread pool (NumPy
releases the GIL); each tile's arithmetic does not depend on the batching.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass

import numpy as np

from ..splatmath import surfel as sf
from ..constants import ALPHA_MIN, T_MIN, TILE_SIZE
from .layers import BatchLayers, RasterLayers
from . import emulation
from .options import Compat, ReferenceOptions
from .stages import ProjectedSplats

#: Pixels per tile.
TILE_PIXELS = TILE_SIZE * TILE_SIZE
#: Splats of every tile evaluated per step (tuned on a 2-core machine).
DEFAULT_CHUNK = 32
#: Tiles per batch (one thread-pool task).
DEFAULT_TILES_PER_BATCH = 64


@dataclass(frozen=True)
class Raster:
    """Per-pixel output of :func:`rasterize` (H rows from the top, W columns).

    color: (H, W, 3) float ``C + T_final background``.  alpha: (H, W) float ``1 - T_final``.
    depth: (H, W) float ``D = sum z alpha T`` (world units, not normalised).
    transmittance: (H, W) float ``T_final``.  n_contrib: (H, W) int32, 1-based position in the
    tile's list of the last splat blended (0: none), as 3DGS's ``n_contrib``.
    n_blended: (H, W) int32, how many splats the pixel blended (alpha >= 1/255, before the
    stop): the "reference fragments", the fill work a renderer that stops exactly must do.
    layers: the further layers a :class:`~splatgl.reference.layers.RasterLayers` asked for,
    as (H, W, ...) images by name (``normal``, ``median_depth``, ``top_id``, ``top_weight``).
    """

    color: np.ndarray
    alpha: np.ndarray
    depth: np.ndarray
    transmittance: np.ndarray
    n_contrib: np.ndarray
    n_blended: np.ndarray | None = None
    layers: dict[str, np.ndarray] | None = None


def gaussian_power(conic: np.ndarray, dx: np.ndarray, dy: np.ndarray) -> np.ndarray:
    """``-0.5 (a dx^2 + c dy^2) - b dx dy`` with ``conic[..., 0:3] = (a, b, c)`` (broadcast)."""
    a, b, c = conic[..., 0], conic[..., 1], conic[..., 2]
    half = np.asarray(-0.5, dtype=np.result_type(conic, dx))
    return half * (a * dx * dx + c * dy * dy) - b * dx * dy


def gaussian_alpha(power: np.ndarray, opacity: np.ndarray, alpha_max: float,
                   alpha_min: float = ALPHA_MIN) -> np.ndarray:
    """``min(alpha_max, o exp(power))``, 0 where ``power > 0`` or the result is below
    ``alpha_min`` (1/255; the ``min_alpha`` emulation knob changes it)."""
    dt = np.result_type(power, opacity).type
    with np.errstate(over="ignore"):
        alpha = np.minimum(dt(alpha_max), opacity * np.exp(power))
    return np.where((power <= 0) & (alpha >= dt(alpha_min)), alpha, dt(0.0))


class _Tiles:
    """Per-tile splat data gathered for one chunk: everything :func:`_blend_chunk` reads."""

    def __init__(self, proj: ProjectedSplats, values: np.ndarray, pos: np.ndarray,
                 valid: np.ndarray):
        sidx = values[np.minimum(pos, values.shape[0] - 1)]
        self.mean2d = proj.mean2d[sidx]      # (n, K, 2)
        self.conic = proj.conic[sidx]        # (n, K, 3)
        self.opacity = proj.opacity[sidx]    # (n, K)
        self.color = proj.color[sidx]        # (n, K, 3)
        self.depth = proj.depth[sidx]        # (n, K)
        self.valid = valid                   # (n, K)
        self.sidx = sidx                     # (n, K) projected rows
        self.wrap_period = proj.wrap_period  # equirect: reach half a turn each side
        if proj.is_surfel:
            self.rows = proj.surfel_rows[sidx]       # (n, K, 3, 3)
            self.depth_rows = proj.depth_rows[sidx]  # (n, K, 3)
        # Emulation (reference/emulation.py): an extent knob's per-pixel clip.
        self.clip_q = None if proj.clip_q is None else proj.clip_q[sidx]           # (n, K)
        self.clip_rows = None if proj.clip_rows is None else proj.clip_rows[sidx]  # (n, K, 2, 2)


def _chunk_alpha(g: _Tiles, px: np.ndarray, py: np.ndarray, alpha_max: float,
                 alpha_min: float = ALPHA_MIN) -> np.ndarray:
    """(n, K, 256) alpha of K splats on the 256 pixels of n tiles (0 where skipped).

    ``px``, ``py``: (n, 16) pixel-centre coordinates of each tile's columns and rows.  The
    quadratic form is separable per axis, so the x and y terms are built on 16 lanes and
    combined with the same operation order as the serial formula.
    """
    dt = px.dtype.type
    dx = px[:, None, :] - g.mean2d[:, :, 0, None]          # (n, K, 16) by column
    dy = py[:, None, :] - g.mean2d[:, :, 1, None]          # (n, K, 16) by row
    axx = g.conic[:, :, 0, None] * dx * dx
    cyy = g.conic[:, :, 2, None] * dy * dy
    bx = g.conic[:, :, 1, None] * dx
    power = dt(-0.5) * (axx[:, :, None, :] + cyy[:, :, :, None]) - bx[:, :, None, :] * dy[:, :, :, None]
    n, k = dx.shape[:2]
    if g.clip_q is not None or g.clip_rows is not None:   # an extent emulation knob
        keep = emulation.clip_mask(power, dx, dy, g.clip_q, g.clip_rows)
        power = np.where(keep, power, dt(-np.inf))
    alpha = gaussian_alpha(power.reshape(n, k, TILE_PIXELS), g.opacity[:, :, None], alpha_max,
                           alpha_min)
    if g.wrap_period is not None:   # equirect: |dx| <= period / 2 (splatgl/cameras/equirect.py)
        reach = np.abs(dx) <= dt(0.5 * g.wrap_period)                  # (n, K, 16) by column
        alpha = np.where(np.broadcast_to(reach[:, :, None, :], power.shape).reshape(n, k, TILE_PIXELS),
                         alpha, dt(0.0))
    return np.where(g.valid[:, :, None], alpha, dt(0.0))


def _surfel_chunk_alpha(g: _Tiles, px: np.ndarray, py: np.ndarray, alpha_max: float,
                        convention: Compat = Compat.INRIA, alpha_min: float = ALPHA_MIN
                        ) -> tuple[np.ndarray, np.ndarray]:
    """2DGS: (n, K, 256) alpha (0 where skipped) and (n, K, 256) view z of the hit.

    :func:`splatgl.splatmath.surfel.surfel_alpha` on the tile's pixel centres, as (n, K, 16 rows,
    16 columns) broadcasts: ``h_u`` varies along columns only, ``h_v`` along rows only.
    """
    dt = px.dtype.type
    dx = (px[:, None, :] - g.mean2d[:, :, 0, None])[:, :, None, :]   # (n, K, 1, 16) by column
    dy = (py[:, None, :] - g.mean2d[:, :, 1, None])[:, :, :, None]   # (n, K, 16, 1) by row
    alpha, z = sf.surfel_alpha(g.rows[:, :, None, None], g.depth_rows[:, :, None, None],
                               g.opacity[:, :, None, None], dx, dy, alpha_max, convention)
    n, k = g.opacity.shape
    alpha = np.broadcast_to(alpha, (n, k, TILE_SIZE, TILE_SIZE)).reshape(n, k, TILE_PIXELS)
    z = np.broadcast_to(z, (n, k, TILE_SIZE, TILE_SIZE)).reshape(n, k, TILE_PIXELS)
    if alpha_min > ALPHA_MIN:                     # the min_alpha emulation knob
        alpha = np.where(alpha >= dt(alpha_min), alpha, dt(0.0))
    return np.where(g.valid[:, :, None], alpha, dt(0.0)), z


def _blend_chunk(t_prev: np.ndarray, alpha: np.ndarray, inclusive_stop: bool
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Blend one chunk: (n, 256) running T, (n, K, 256) alphas (0 for skipped or stopped).

    Returns ``(weights (n, K, 256) = alpha T for blended splats, 0 otherwise,
    n_blended (n, 256) prefix length kept, t_seq (n, K + 1, 256))`` where ``t_seq[:, 0]`` is
    ``t_prev`` and ``t_seq[:, k + 1]`` the running product after splat k (before the stop test).
    """
    n, k, p = alpha.shape
    t_seq = np.empty((n, k + 1, p), alpha.dtype)
    t_seq[:, 0] = t_prev
    np.subtract(alpha.dtype.type(1.0), alpha, out=t_seq[:, 1:])
    np.cumprod(t_seq, axis=1, out=t_seq)
    t_min = alpha.dtype.type(T_MIN)
    kept = t_seq[:, 1:] > t_min if inclusive_stop else t_seq[:, 1:] >= t_min
    weights = np.where(kept, alpha, alpha.dtype.type(0.0)) * t_seq[:, :-1]
    return weights, kept.sum(axis=1), t_seq


def _raster_batch(proj: ProjectedSplats, values: np.ndarray, ranges: np.ndarray,
                  tiles: np.ndarray, options: ReferenceOptions, chunk: int,
                  extra: BatchLayers | None = None):
    """Blend the tiles ``tiles`` (b,) completely; returns (T, C, D, n_contrib, n_blended) per
    tile pixel (and fills ``extra``, the further layers of these tiles)."""
    dt = proj.dtype.type
    b = tiles.shape[0]
    out_t = np.ones((b, TILE_PIXELS), proj.dtype)
    out_c = np.zeros((b, TILE_PIXELS, 3), proj.dtype)
    out_d = np.zeros((b, TILE_PIXELS), proj.dtype)
    out_n = np.zeros((b, TILE_PIXELS), np.int32)
    out_b = np.zeros((b, TILE_PIXELS), np.int32)
    start, end = ranges[tiles, 0], ranges[tiles, 1]
    rows = np.flatnonzero(end > start)
    lanes = np.arange(TILE_SIZE, dtype=np.float64) + 0.5
    gw = proj.grid[0]
    px = ((tiles % gw)[:, None] * TILE_SIZE + lanes).astype(proj.dtype)
    py = ((tiles // gw)[:, None] * TILE_SIZE + lanes).astype(proj.dtype)
    t, c, d, nc, nb = out_t[rows], out_c[rows], out_d[rows], out_n[rows], out_b[rows]
    done = np.zeros((rows.size, TILE_PIXELS), bool)
    if extra is not None:
        extra.start(rows)
    amax, inclusive = options.resolved_alpha_max, options.stop_inclusive
    ks = np.arange(chunk)
    offset = 0
    while rows.size:
        pos = start[rows, None] + offset + ks
        g = _Tiles(proj, values, pos, pos < end[rows, None])
        if proj.is_surfel:
            alpha, z_pix = _surfel_chunk_alpha(g, px[rows], py[rows], amax, options.compat,
                                               options.alpha_min)
        else:
            alpha = _chunk_alpha(g, px[rows], py[rows], amax, options.alpha_min)
        alpha = np.where(done[:, None, :], dt(0.0), alpha)
        if extra is not None:                               # geometry in front: not blended
            z_splat = z_pix if proj.is_surfel else g.depth[:, :, None]
            alpha = extra.depth_test(alpha, z_splat)
        w, kept, t_seq = _blend_chunk(t, alpha, inclusive)
        wt = w.transpose(0, 2, 1)                           # (n, 256, K)
        c += np.matmul(wt, g.color)
        if proj.is_surfel:                                  # depth of the hit, per pixel
            d += (w * np.where(w > 0, z_pix, dt(0.0))).sum(axis=1)
        else:
            d += np.matmul(wt, g.depth[:, :, None])[:, :, 0]
        if extra is not None:
            extra.add(g.sidx, w, t_seq, z_splat)
        t = np.take_along_axis(t_seq, kept[:, None, :], axis=1)[:, 0]
        done |= kept < chunk
        blended = w > 0
        nb = nb + blended.sum(axis=1, dtype=np.int32)
        last = chunk - np.argmax(blended[:, ::-1, :], axis=1)   # 1-based within the chunk
        nc = np.where(blended.any(axis=1), offset + last, nc).astype(np.int32)
        offset += chunk
        go = ~done.all(axis=1) & (start[rows] + offset < end[rows])
        if not go.all():
            stop = ~go
            out_t[rows[stop]], out_c[rows[stop]] = t[stop], c[stop]
            out_d[rows[stop]], out_n[rows[stop]] = d[stop], nc[stop]
            out_b[rows[stop]] = nb[stop]
            if extra is not None:
                extra.retire(stop, go)
            rows, t, c, d, nc, nb, done = rows[go], t[go], c[go], d[go], nc[go], nb[go], done[go]
    return out_t, out_c, out_d, out_n, out_b


def _untile(per_tile: np.ndarray, grid: tuple[int, int], height: int, width: int) -> np.ndarray:
    """(tiles, 256, ...) -> (H, W, ...) image, cropping the partial tiles at the edges."""
    gw, gh = grid
    rest = per_tile.shape[2:]
    img = per_tile.reshape((gh, gw, TILE_SIZE, TILE_SIZE) + rest).swapaxes(1, 2)
    return np.ascontiguousarray(img.reshape((gh * TILE_SIZE, gw * TILE_SIZE) + rest)[:height, :width])


def rasterize(proj: ProjectedSplats, sorted_values: np.ndarray, ranges: np.ndarray,
              background=(0.0, 0.0, 0.0), options: ReferenceOptions | None = None,
              chunk: int = DEFAULT_CHUNK, tiles_per_batch: int = DEFAULT_TILES_PER_BATCH,
              workers: int | None = None, progress=None,
              layers: RasterLayers | None = None, batch=None) -> Raster:
    """Blend every tile's sorted splat list into the image (the reference's last stage).

    Args:
        proj: output of :func:`~splatgl.reference.stages.project` (its dtype is used throughout).
        sorted_values: (M,) int64 splat indices in sorted key order (:func:`sort`).
        ranges: (tiles, 2) int64 ``[start, end)`` per tile (:func:`tile_ranges`).
        background: RGB composited as ``C + T_final background``.
        options: alpha clamp and stop rule (default INRIA).
        chunk, tiles_per_batch, workers: vectorisation knobs; the result does not depend on
            them beyond float summation order of C and D (T and n_contrib are exact).
        progress: optional ``progress(tiles_done, busy_tiles, what)``
            (:mod:`splatgl.progress`), called as each batch of tiles finishes.  Ctrl-C lands
            between batches: batches not yet started are cancelled.
        layers: the further layers to compute and the geometry to test against
            (:mod:`splatgl.reference.layers`), or None.
        batch: what blends one batch of tiles (default the global order's; the per-pixel
            order passes its own, :mod:`splatgl.reference.per_pixel`).
    """
    options = ReferenceOptions() if options is None else options
    if chunk < 1 or tiles_per_batch < 1:
        raise ValueError("chunk and tiles_per_batch must be positive")
    n_tiles = proj.n_tiles
    busy = np.flatnonzero(ranges[:, 1] > ranges[:, 0])
    # Interleave busy tiles across batches so that dense regions spread over all workers.
    n_batches = max(1, -(-busy.size // tiles_per_batch))
    batches = [busy[i::n_batches] for i in range(n_batches)] if busy.size else []
    workers = workers or min(os.cpu_count() or 1, 8)
    t = np.ones((n_tiles, TILE_PIXELS), proj.dtype)
    c = np.zeros((n_tiles, TILE_PIXELS, 3), proj.dtype)
    d = np.zeros((n_tiles, TILE_PIXELS), proj.dtype)
    nc = np.zeros((n_tiles, TILE_PIXELS), np.int32)
    nb = np.zeros((n_tiles, TILE_PIXELS), np.int32)
    values = np.asarray(sorted_values, np.int64)
    under = layers.tiled_under(proj.grid) if layers is not None else None


    def run(tiles: np.ndarray):
        extra = (layers.batch(len(tiles), proj.dtype, under[tiles] if under is not None else None)
                 if layers is not None else None)
        if batch is None:
            return tiles, _raster_batch(proj, values, ranges, tiles, options, chunk, extra), extra
        return tiles, batch(proj, values, ranges, tiles, options, chunk), extra

    results, done = [], 0

    def finished(item) -> None:
        nonlocal done
        results.append(item)
        done += len(item[0])
        if progress is not None:
            progress(done, busy.size, "reference: rasterizing tiles")

    with np.errstate(under="ignore"):
        if workers > 1 and len(batches) > 1:
            pool = ThreadPoolExecutor(workers)
            try:
                for future in as_completed([pool.submit(run, b) for b in batches]):
                    finished(future.result())
            finally:  # on Ctrl-C: drop the queued batches, do not wait for them
                pool.shutdown(wait=False, cancel_futures=True)
        else:
            for b in batches:
                finished(run(b))
    for tiles, (bt, bc, bd, bn, bb), _ in results:
        t[tiles], c[tiles], d[tiles], nc[tiles], nb[tiles] = bt, bc, bd, bn, bb
    bg = np.asarray(background, proj.dtype)
    h, w = proj.height, proj.width
    t_img = _untile(t, proj.grid, h, w)
    color = _untile(c, proj.grid, h, w) + t_img[..., None] * bg
    extra = _gather_layers(layers, results, n_tiles, proj) if layers is not None else None
    return Raster(color=color, alpha=proj.dtype.type(1.0) - t_img,
                  depth=_untile(d, proj.grid, h, w), transmittance=t_img,
                  n_contrib=_untile(nc, proj.grid, h, w), n_blended=_untile(nb, proj.grid, h, w),
                  layers=extra)


def _gather_layers(layers: RasterLayers, results, n_tiles: int, proj: ProjectedSplats
                   ) -> dict[str, np.ndarray]:
    """The batches' further layers as (H, W, ...) images (empty tiles at their start values)."""
    empty = layers.batch(n_tiles, proj.dtype, None).out
    for tiles, _, extra in results:
        for name, a in extra.out.items():
            empty[name][tiles] = a
    return {name: _untile(a, proj.grid, proj.height, proj.width) for name, a in empty.items()}


def transmittance_trace(proj: ProjectedSplats, sorted_values: np.ndarray, ranges: np.ndarray,
                        tile: int, options: ReferenceOptions | None = None) -> np.ndarray:
    """T of each of a tile's 256 pixels after each splat of its list, for inspection and tests.

    Returns (L + 1, 256) in the projection dtype: row 0 is 1, row k + 1 the transmittance after
    the tile's k-th splat (frozen once the pixel has stopped).  Uses the same per-chunk code as
    :func:`rasterize` with the whole list as one chunk.
    """
    options = ReferenceOptions() if options is None else options
    start, end = (int(v) for v in ranges[tile])
    length = end - start
    t = np.ones((1, TILE_PIXELS), proj.dtype)
    if length == 0:
        return t
    lanes = np.arange(TILE_SIZE, dtype=np.float64) + 0.5
    gw = proj.grid[0]
    px = ((tile % gw) * TILE_SIZE + lanes).astype(proj.dtype)[None]
    py = ((tile // gw) * TILE_SIZE + lanes).astype(proj.dtype)[None]
    pos = start + np.arange(length)[None]
    g = _Tiles(proj, np.asarray(sorted_values, np.int64), pos, pos < end)
    with np.errstate(under="ignore"):
        if proj.is_surfel:
            alpha, _ = _surfel_chunk_alpha(g, px, py, options.resolved_alpha_max, options.compat,
                                           options.alpha_min)
        else:
            alpha = _chunk_alpha(g, px, py, options.resolved_alpha_max, options.alpha_min)
        _, kept, t_seq = _blend_chunk(t, alpha, options.stop_inclusive)
    final = np.take_along_axis(t_seq, kept[:, None, :], axis=1)
    ks = np.arange(length + 1)[None, :, None]
    return np.where(ks <= kept[:, None, :], t_seq, final)[0]
