"""``render_reference``: the five reference stages chained into one image."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..cameras.camera import Camera
from ..cameras.view import View
from ..model.scene import Scene
from ..model.settings import Order, RenderSettings
from .binning import emit_keys, sort, tile_ranges
from .options import Compat, ReferenceOptions, as_options
from .per_pixel import rasterize_per_pixel
from .rasterize import rasterize
from .stages import ProjectedSplats, project


@dataclass(frozen=True)
class ReferenceImage:
    """A reference render (H rows, row 0 at the top; float = the render dtype).

    Attributes:
        color: (H, W, 3) float, composited with the background: ``C + T_final bg``.
        alpha: (H, W) float ``1 - T_final``.
        depth: (H, W) float accumulated ``D = sum z alpha T`` (view z, world units; not
            divided by alpha).
        transmittance: (H, W) float ``T_final``.
        n_contrib: (H, W) int32 1-based position of the last blended splat in the pixel's tile
            list (0: none).
        projected: the ``project`` stage's output (per-splat arrays).
        sorted_values: (M,) int64 splat index per sorted key.  ranges: (tiles, 2) int64.
        options: the convention used.
        n_blended: (H, W) int32 splats blended per pixel (alpha >= 1/255, before the stop);
            its sum is the "reference fragments" the benchmark compares fill work with.
    """

    color: np.ndarray
    alpha: np.ndarray
    depth: np.ndarray
    transmittance: np.ndarray
    n_contrib: np.ndarray
    projected: ProjectedSplats
    sorted_values: np.ndarray
    ranges: np.ndarray
    options: ReferenceOptions
    n_blended: np.ndarray | None = None

    @property
    def rgba(self) -> np.ndarray:
        """(H, W, 4) float32: composited colour and alpha."""
        return np.concatenate([self.color, self.alpha[..., None]], -1).astype(np.float32)


def render_reference(scene: Scene, camera: Camera, settings: RenderSettings | None = None,
                     dtype: np.dtype | type = np.float32,
                     compat: Compat | ReferenceOptions | str = Compat.INRIA,
                     progress=None) -> ReferenceImage:
    """Render ``scene`` with the NumPy per-tile reference rasterizer.

    Args:
        scene: a 3DGS or 2DGS (surfel) scene.
        camera: any camera model the reference draws; the image is camera.height x
            camera.width.  The frame's :class:`~splatgl.cameras.view.View` is built from it,
            the settings and the scene (model transform, near plane, anchor).
        settings: background, near plane, antialiasing, SH cap, model transform, emulation
            knobs and order (default RenderSettings()).
        dtype: float32 (GPU-like) or float64.
        compat: a :class:`Compat` (INRIA default, GSPLAT) or a full :class:`ReferenceOptions`.
        progress: optional :data:`splatgl.progress.ProgressCallback`, told the tiles rasterized.
    """
    settings = RenderSettings() if settings is None else settings
    options = with_settings(as_options(compat), settings)
    proj = project(scene, View.of(camera, settings, scene), settings, dtype, options)
    keys, values = emit_keys(proj)
    keys, values = sort(keys, values)
    ranges = tile_ranges(keys, proj.n_tiles)
    if options.order is Order.PER_PIXEL:
        raster = rasterize_per_pixel(proj, values, ranges, camera, settings.background, options,
                                     progress=progress)
    else:
        raster = rasterize(proj, values, ranges, settings.background, options, progress=progress)
    return ReferenceImage(color=raster.color, alpha=raster.alpha, depth=raster.depth,
                          transmittance=raster.transmittance, n_contrib=raster.n_contrib,
                          projected=proj, sorted_values=values, ranges=ranges, options=options,
                          n_blended=raster.n_blended)


def with_settings(options: ReferenceOptions, settings: RenderSettings) -> ReferenceOptions:
    """``options`` with the reference's parts of ``settings`` (:class:`RenderSettings`): its
    emulation knobs (unless ``options`` brings its own) and its order."""
    changes = {}
    if not settings.emulation.is_default and options.emulation.is_default:
        changes["emulation"] = settings.emulation
    if settings.order is Order.PER_PIXEL:
        changes["order"] = Order.PER_PIXEL
    return dataclasses.replace(options, **changes) if changes else options


def render_reference_rgba(scene: Scene, camera: Camera, settings: RenderSettings | None = None,
                          dtype: np.dtype | type = np.float32,
                          compat: Compat | ReferenceOptions | str = Compat.INRIA) -> np.ndarray:
    """(H, W, 4) float32 RGBA of :func:`render_reference` (colour composited, row 0 on top)."""
    return render_reference(scene, camera, settings, dtype, compat).rgba
