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

Order: the one rasterizer draws both orders of ``options.order``; the per-pixel order
(``--order per-pixel``) blends each batch of tiles by :func:`splatgl.reference.per_pixel.raster_batch`
instead, on the same per-chunk arithmetic (:mod:`splatgl.reference.chunk`).
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass

import numpy as np

from ..constants import TILE_SIZE
from ..scene.settings import Order
from . import per_pixel
from .chunk import (TILE_PIXELS, ChunkSplats, blend_chunk, chunk_alpha, surfel_chunk_alpha,
                    tile_centres, tile_outputs)
from .layers import BatchLayers, RasterLayers
from .options import ReferenceOptions
from .stages import ProjectedSplats

#: Splats of every tile evaluated per step (tuned on a 2-core machine).
DEFAULT_CHUNK = 32
#: Tiles per batch (one thread-pool task), by order: the per-pixel order's tiles cost more.
DEFAULT_TILES_PER_BATCH = {Order.GLOBAL: 64, Order.PER_PIXEL: 4}


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


def _raster_batch(proj: ProjectedSplats, values: np.ndarray, ranges: np.ndarray,
                  tiles: np.ndarray, options: ReferenceOptions, chunk: int,
                  extra: BatchLayers | None = None):
    """Blend the tiles ``tiles`` (b,) completely; returns (T, C, D, n_contrib, n_blended) per
    tile pixel (and fills ``extra``, the further layers of these tiles)."""
    dt = proj.dtype.type
    out_t, out_c, out_d, out_n, out_b = tile_outputs(tiles.shape[0], proj.dtype)
    start, end = ranges[tiles, 0], ranges[tiles, 1]
    rows = np.flatnonzero(end > start)
    px, py = tile_centres(tiles, proj)
    t, c, d, nc, nb = out_t[rows], out_c[rows], out_d[rows], out_n[rows], out_b[rows]
    done = np.zeros((rows.size, TILE_PIXELS), bool)
    if extra is not None:
        extra.start(rows)
    amax, inclusive = options.resolved_alpha_max, options.stop_inclusive
    ks = np.arange(chunk)
    offset = 0
    while rows.size:
        pos = start[rows, None] + offset + ks
        g = ChunkSplats(proj, values, pos, pos < end[rows, None])
        if proj.is_surfel:
            alpha, z_pix = surfel_chunk_alpha(g, px[rows], py[rows], amax, options.compat,
                                              options.alpha_min)
        else:
            alpha = chunk_alpha(g, px[rows], py[rows], amax, options.alpha_min)
        alpha = np.where(done[:, None, :], dt(0.0), alpha)
        if extra is not None:                               # geometry in front: not blended
            z_splat = z_pix if proj.is_surfel else g.depth[:, :, None]
            alpha = extra.depth_test(alpha, z_splat)
        w, kept, t_seq = blend_chunk(t, alpha, inclusive)
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
              chunk: int = DEFAULT_CHUNK, tiles_per_batch: int | None = None,
              workers: int | None = None, progress=None,
              layers: RasterLayers | None = None) -> Raster:
    """Blend every tile's sorted splat list into the image (the reference's last stage), in
    the order ``options.order`` names: global (3DGS: each tile's list as sorted by depth) or
    per pixel (each pixel's contributions re-sorted by the depth of their peak along its ray,
    exactly or by the tile renderer's window, :mod:`splatgl.reference.per_pixel`).

    Args:
        proj: output of :func:`~splatgl.reference.stages.project` (its dtype is used throughout).
        sorted_values: (M,) int64 splat indices in sorted key order (:func:`sort`).
        ranges: (tiles, 2) int64 ``[start, end)`` per tile (:func:`tile_ranges`).
        background: RGB composited as ``C + T_final background``.
        options: alpha clamp, stop rule and order (default INRIA, global).  The per-pixel
            order needs ``proj`` projected with it (its ``peak`` and ``rays``; 2DGS surfels
            sort by the view z of the ray's hit) and computes no further ``layers``.
        chunk, tiles_per_batch, workers: vectorisation knobs; the result does not depend on
            them beyond float summation order of C and D (T and n_contrib are exact).
            ``tiles_per_batch`` defaults by order (:data:`DEFAULT_TILES_PER_BATCH`).
        progress: optional ``progress(tiles_done, busy_tiles, what)``
            (:mod:`splatgl.progress`), called as each batch of tiles finishes.  Ctrl-C lands
            between batches: batches not yet started are cancelled.
        layers: the further layers to compute and the geometry to test against
            (:mod:`splatgl.reference.layers`), or None.
    """
    options = ReferenceOptions() if options is None else options
    per_pixel_order = options.order is Order.PER_PIXEL
    if per_pixel_order:
        per_pixel.check_projection(proj, layers)
    if tiles_per_batch is None:
        tiles_per_batch = DEFAULT_TILES_PER_BATCH[options.order]
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
        if per_pixel_order:
            return tiles, per_pixel.raster_batch(proj, values, ranges, tiles, options), extra
        return tiles, _raster_batch(proj, values, ranges, tiles, options, chunk, extra), extra

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
    px, py = tile_centres(np.array([tile]), proj)
    pos = start + np.arange(length)[None]
    g = ChunkSplats(proj, np.asarray(sorted_values, np.int64), pos, pos < end)
    with np.errstate(under="ignore"):
        if proj.is_surfel:
            alpha, _ = surfel_chunk_alpha(g, px, py, options.resolved_alpha_max, options.compat,
                                          options.alpha_min)
        else:
            alpha = chunk_alpha(g, px, py, options.resolved_alpha_max, options.alpha_min)
        _, kept, t_seq = blend_chunk(t, alpha, options.stop_inclusive)
    final = np.take_along_axis(t_seq, kept[:, None, :], axis=1)
    ks = np.arange(length + 1)[None, :, None]
    return np.where(ks <= kept[:, None, :], t_seq, final)[0]
