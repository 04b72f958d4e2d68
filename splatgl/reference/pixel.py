"""Which splats make one pixel: the reference's front-to-back list at that pixel
(``splatgl pixel``, the viewer's Ctrl+click).

The pixel's tile list is the one :func:`~splatgl.reference.rasterize.rasterize` blends (the
splats whose tile rectangle holds the pixel's tile, by the low 32 bits of their keys, then by
row, as the stable key sort orders them), built for that tile alone; every splat of it is
evaluated at the pixel centre with the rasterizer's own functions and blended in order, so each
weight ``alpha T`` is the one the full render adds and the weights sum to the pixel's alpha.

The listing follows the rules the settings give the reference, as
:func:`~splatgl.reference.render.render_reference` does: the emulation knobs (their keys,
extents, alpha limits) and the per-pixel order (each pixel's contributions sorted by the depth
of their peak along its ray, :mod:`splatgl.reference.per_pixel`; the depth listed is that peak's).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from ..cameras.camera import Camera
from ..cameras.view import View
from ..constants import TILE_SIZE
from ..errors import SplatglError
from ..scene.splats import Scene
from ..scene.settings import Order, RenderSettings
from ..output.under import UnderLayer
from .binning import depth_bits
from .options import Compat, ReferenceOptions, as_options
from ..splatmath.peak import Rays, tile_key_bits
from .per_pixel import _contributions, exact_order, window_order
from .chunk import ChunkSplats, blend_chunk, chunk_alpha, surfel_chunk_alpha
from .render import PER_PIXEL_LAYERS_REFUSED, with_settings
from .stages import ProjectedSplats, project


@dataclass(frozen=True)
class PixelSplat:
    """One splat blended into the pixel: its scene ``index`` (row), ``depth`` (the splat's z:
    view z, a lens camera's distance, a surfel's hit), ``alpha`` at the pixel centre,
    ``weight = alpha T_before`` and ``transmittance`` ``T`` after it; ``color`` its RGB."""

    index: int
    depth: float
    alpha: float
    weight: float
    transmittance: float
    color: tuple[float, float, float]


@dataclass(frozen=True)
class PixelListing:
    """The splats of pixel (``x``, ``y``) (column, row from the top-left), front to back.

    ``color`` is ``C + T background`` and ``alpha`` ``1 - T`` of the pixel, as the reference
    renders it; ``candidates`` the length of its tile's list; ``stopped_by`` the scene row of
    the splat at which blending stopped (``T (1 - alpha) < 1e-4``: it and every later one are
    left out), or None; ``hidden`` the splats dropped by the geometry's depth (``--under``).
    """

    x: int
    y: int
    splats: tuple[PixelSplat, ...]
    color: tuple[float, float, float]
    alpha: float
    candidates: int
    stopped_by: int | None
    hidden: int = 0

    @property
    def weight_sum(self) -> float:
        return float(sum(s.weight for s in self.splats))

    def to_json(self) -> dict:
        return asdict(self) | {"weight_sum": self.weight_sum}

    def table(self, limit: int | None = None) -> str:
        """The listing as text: one line per splat (at most ``limit``), then the pixel."""
        lines = [f"pixel ({self.x}, {self.y}): {len(self.splats)} splats blended of "
                 f"{self.candidates} in its tile, front to back" if self.splats else
                 f"pixel ({self.x}, {self.y}): no splat reaches it ({self.candidates} in its tile)"]
        if self.splats:
            lines.append(f"{'#':>4}  {'index':>9}  {'depth':>10}  {'alpha':>8}  {'weight':>8}  "
                         f"{'T after':>8}  colour")
        shown = self.splats if limit is None else self.splats[:limit]
        for k, s in enumerate(shown):
            rgb = ", ".join(f"{c:.3f}" for c in s.color)
            lines.append(f"{k:>4}  {s.index:>9}  {s.depth:>10.5g}  {s.alpha:>8.5f}  "
                         f"{s.weight:>8.5f}  {s.transmittance:>8.5f}  ({rgb})")
        if len(shown) < len(self.splats):
            lines.append(f"   ... {len(self.splats) - len(shown)} more")
        if self.stopped_by is not None:
            lines.append(f"stopped at splat {self.stopped_by} (T would fall below 1e-4)")
        if self.hidden:
            lines.append(f"{self.hidden} splats behind the geometry left out")
        rgb = ", ".join(f"{c:.5f}" for c in self.color)
        lines.append(f"weights sum {self.weight_sum:.6f} = alpha {self.alpha:.6f}; colour ({rgb})")
        return "\n".join(lines)


def check_pixel(x: int, y: int, width: int, height: int, what: str = "--at") -> None:
    """Refuse, in one line, a pixel outside a ``width`` x ``height`` image."""
    if not (0 <= x < width and 0 <= y < height):
        raise SplatglError(f"{what} {x},{y}: outside the {width}x{height} image "
                           f"(columns 0..{width - 1}, rows 0..{height - 1})")


def pixel_splats(scene: Scene, camera: Camera, x: int, y: int,
                 settings: RenderSettings | None = None,
                 compat: Compat | ReferenceOptions | str = Compat.INRIA,
                 under: UnderLayer | None = None, dtype=np.float32) -> PixelListing:
    """The splats that blend into pixel (``x``, ``y``) of ``camera``'s image (module doc): the
    pixel of ``render_reference(scene, camera, settings, dtype, compat, under=under)``."""
    settings = RenderSettings() if settings is None else settings
    check_pixel(x, y, camera.width, camera.height)
    options = with_settings(as_options(compat), settings)
    if under is not None and options.order is Order.PER_PIXEL:
        raise SplatglError(PER_PIXEL_LAYERS_REFUSED)
    proj = project(scene, View.of(camera, settings, scene), settings, dtype, options)
    tx, ty = x // TILE_SIZE, y // TILE_SIZE
    rows = _tile_list(proj, tx, ty)
    bg = np.asarray(settings.background, np.float64)
    if rows.size == 0:
        return PixelListing(x, y, (), tuple(float(v) for v in bg), 0.0, 0, None)
    dt = proj.dtype.type
    lanes = np.arange(TILE_SIZE, dtype=np.float64) + 0.5
    px = (tx * TILE_SIZE + lanes).astype(proj.dtype)
    py = (ty * TILE_SIZE + lanes).astype(proj.dtype)
    lane = (y % TILE_SIZE) * TILE_SIZE + x % TILE_SIZE
    with np.errstate(under="ignore"):
        if options.order is Order.PER_PIXEL:
            seq, alpha, z = _per_pixel_sequence(proj, rows, px, py, lane, Rays.of(camera), options)
        else:
            seq, alpha, z = _global_sequence(proj, rows, px, py, lane, options)
        hidden = 0
        if under is not None:
            behind = (z >= under.depth[y, x]) & (alpha > 0)
            hidden = int(behind.sum())
            alpha = np.where(behind, dt(0.0), alpha)
        w, kept, t_seq = blend_chunk(np.ones((1, 1), proj.dtype), alpha[None, :, None],
                                     options.stop_inclusive)
    w, t_seq, kept = w[0, :, 0], t_seq[0, :, 0], int(kept[0, 0])
    source = proj.source if proj.source is not None else np.arange(proj.count)
    splats = tuple(PixelSplat(int(source[seq[k]]), float(z[k]), float(alpha[k]),
                              float(w[k]), float(t_seq[k + 1]),
                              tuple(float(c) for c in proj.color[seq[k]]))
                   for k in range(kept) if w[k] > 0)
    t_final = float(t_seq[kept])
    stopped = int(source[seq[kept]]) if kept < seq.size else None
    color = sum((np.asarray(s.color) * s.weight for s in splats), np.zeros(3)) + t_final * bg
    if under is not None:
        color = color - t_final * bg + t_final * (under.rgb[y, x] + (1.0 - under.alpha[y, x]) * bg)
    return PixelListing(x, y, splats, tuple(float(c) for c in color), 1.0 - t_final, int(rows.size),
                        stopped, hidden)


def _tile_list(proj: ProjectedSplats, tx: int, ty: int) -> np.ndarray:
    """The projected rows of tile (``tx``, ``ty``)'s list in the order the stable key sort gives
    them (:func:`splatgl.reference.binning.emit_keys`, for this tile alone)."""
    holds = (proj.visible & (proj.rect_min[:, 0] <= tx) & (tx < proj.rect_max[:, 0])
             & (proj.rect_min[:, 1] <= ty) & (ty < proj.rect_max[:, 1]))
    rows = np.flatnonzero(holds)
    if proj.peak is not None and proj.rays is not None:     # per-pixel order: depth at the tile
        n = rows.size
        low = tile_key_bits(proj.peak[rows], proj.mean2d[rows], np.full(n, tx, np.int64),
                            np.full(n, ty, np.int64), proj.rays, TILE_SIZE)
    else:
        low = (depth_bits(proj.depth) if proj.key_bits is None else proj.key_bits)[rows]
    return rows[np.lexsort((rows, low))]


def _global_sequence(proj: ProjectedSplats, rows: np.ndarray, px: np.ndarray, py: np.ndarray,
                     lane: int, options: ReferenceOptions):
    """The global order: the tile's list as it is, with each splat's alpha and depth at the
    pixel; ``(rows (L,), alpha (L,), depth (L,))``."""
    pos = np.arange(rows.size)[None]
    g = ChunkSplats(proj, rows, pos, pos < rows.size)
    if proj.is_surfel:
        alpha, z = surfel_chunk_alpha(g, px[None], py[None], options.resolved_alpha_max,
                                      options.compat, options.alpha_min)
        z = z[0, :, lane]
    else:
        alpha = chunk_alpha(g, px[None], py[None], options.resolved_alpha_max, options.alpha_min)
        z = g.depth[0]
    return rows, alpha[0, :, lane], z


def _per_pixel_sequence(proj: ProjectedSplats, rows: np.ndarray, px: np.ndarray, py: np.ndarray,
                        lane: int, rays: Rays, options: ReferenceOptions):
    """The per-pixel order: the pixel's contributions sorted as
    :func:`splatgl.reference.rasterize.rasterize` (per-pixel order) sorts them (exactly, or by the tile
    renderer's window), with the depth of each splat's peak along the ray."""
    pix, pos, t, alpha, _ = _contributions(proj, rows, 0, rows.size, px, py, rays, options)
    idx = (exact_order(pix, pos, t) if options.window is None
           else window_order(pix, pos, t, options.window))
    idx = idx[pix[idx] == lane]
    return rows[pos[idx]], alpha[idx], t[idx]
