"""``render_reference``: the five reference stages chained into one image."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..cameras.camera import Camera
from ..cameras.equirect import eye_space
from ..cameras.view import View
from ..errors import SplatglError
from ..scene.splats import Scene, SplatKind
from ..scene.settings import Order, RenderSettings
from ..output.layers import BASE, Layer, RenderOutput
from ..output.under import UnderLayer, composite_depth, composite_under
from ..splatmath import project as pm
from ..splatmath.normals import splat_normals
from .binning import emit_keys, sort, tile_ranges
from .layers import RasterLayers
from .options import Compat, ReferenceOptions, as_options
from .rasterize import rasterize
from .stages import ProjectedSplats, project


#: Why the per-pixel order refuses geometry and the further layers (render and pixel alike).
PER_PIXEL_LAYERS_REFUSED = ("--order per-pixel draws colour, alpha and depth only: it cannot be "
                            "combined with --under or the normal, median-depth, count and top-id "
                            "layers yet")


@dataclass(frozen=True)
class ReferenceImage:
    """A reference render (H rows, row 0 at the top; float = the render dtype).

    Attributes:
        color: (H, W, 3) float, composited with the background: ``C + T_final bg`` (with
            geometry under the splats: :func:`splatgl.output.under.composite_under`).
        alpha: (H, W) float ``1 - T_final`` (with geometry under the splats, the composite's
            ``1 - T_final (1 - U_a)``).
        depth: (H, W) float accumulated ``D = sum z alpha T`` (view z, world units; not
            divided by alpha; with geometry, :func:`splatgl.output.under.composite_depth`).
        transmittance: (H, W) float ``T_final``.
        n_contrib: (H, W) int32 1-based position of the last blended splat in the pixel's tile
            list (0: none).
        projected: the ``project`` stage's output (per-splat arrays).
        sorted_values: (M,) int64 splat index per sorted key.  ranges: (tiles, 2) int64.
        options: the convention used.
        n_blended: (H, W) int32 splats blended per pixel (alpha >= 1/255, before the stop);
            its sum is the "reference fragments" the benchmark compares fill work with, and it
            is the count layer.
        layers: the further layers asked for (:mod:`splatgl.reference.layers`): ``normal``
            (H, W, 3) accumulated camera-space normal, ``median_depth`` (H, W), ``top_id``
            (H, W) int64 and ``top_weight`` (H, W); None when none was asked for.
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
    layers: dict[str, np.ndarray] | None = None

    @property
    def rgba(self) -> np.ndarray:
        """(H, W, 4) float32: composited colour and alpha."""
        return np.concatenate([self.color, self.alpha[..., None]], -1).astype(np.float32)

    def output(self, layers: frozenset[Layer]) -> RenderOutput:
        """The ``layers`` of this render as the GPU renderers return them (float32; the depth
        always, which the reference computes anyway)."""
        extra = self.layers or {}
        planes: dict[str, np.ndarray] = {}
        if Layer.NORMAL in layers:
            planes["normal"] = extra["normal"].astype(np.float32)
        if Layer.MEDIAN_DEPTH in layers:
            planes["median_depth"] = extra["median_depth"].astype(np.float32)
        if Layer.COUNT in layers:
            planes["count"] = self.n_blended.astype(np.uint32)
        if Layer.TOP_ID in layers:
            planes["top_id"] = extra["top_id"]
        return RenderOutput(self.rgba, np.asarray(self.depth, np.float32),
                            frozenset(layers) | {Layer.DEPTH}, **planes)


def row_normals(scene: Scene, view: View, proj: ProjectedSplats) -> np.ndarray:
    """(rows, 3) unit camera-space normals of ``proj``'s rows, in its dtype
    (:func:`splatgl.splatmath.normals.splat_normals` at the centres the projection used)."""
    means, camera = pm.anchored(scene.means, view.anchor, view.camera, proj.dtype)
    p_cam = eye_space(pm.to_camera(means, camera), camera)
    normals = splat_normals(scene.rotations, scene.scales, p_cam, camera.rotation,
                            camera.model.parallel_rays, scene.kind is SplatKind.SURFEL_2D)
    return normals if proj.source is None else normals[proj.source]


def render_reference(scene: Scene, camera: Camera, settings: RenderSettings | None = None,
                     dtype: np.dtype | type = np.float32,
                     compat: Compat | ReferenceOptions | str = Compat.INRIA,
                     progress=None, layers: frozenset[Layer] = BASE,
                     under: UnderLayer | None = None) -> ReferenceImage:
    """Render ``scene`` with the NumPy per-tile reference rasterizer.

    Args:
        scene: a 3DGS or 2DGS (surfel) scene.
        camera: any camera model the reference draws; the image is camera.height x
            camera.width.  The frame's :class:`~splatgl.cameras.view.View` is built from it,
            the settings and the scene (scene transform, near plane, anchor).
        settings: background, near plane, antialiasing, SH cap, scene transform, emulation
            knobs and order (default RenderSettings()).
        dtype: float32 (GPU-like) or float64.
        compat: a :class:`Compat` (INRIA default, GSPLAT) or a full :class:`ReferenceOptions`.
        progress: optional :data:`splatgl.progress.ProgressCallback`, told the tiles rasterized.
        layers: the layers wanted; colour, alpha, depth and the count are always computed,
            the normal, median depth and top contributor only when asked for.
        under: geometry to composite into (:mod:`splatgl.output.under`): splats at or behind
            its depth are dropped, and the rest composited over its colour.
    """
    settings = RenderSettings() if settings is None else settings
    options = with_settings(as_options(compat), settings)
    view = View.of(camera, settings, scene)
    proj = project(scene, view, settings, dtype, options)
    keys, values = emit_keys(proj)
    keys, values = sort(keys, values)
    ranges = tile_ranges(keys, proj.n_tiles)
    extra = None
    if under is not None or layers & {Layer.NORMAL, Layer.MEDIAN_DEPTH, Layer.TOP_ID}:
        extra = RasterLayers(
            normals=row_normals(scene, view, proj) if Layer.NORMAL in layers else None,
            median=Layer.MEDIAN_DEPTH in layers, top=Layer.TOP_ID in layers, source=proj.source,
            under_depth=None if under is None else under.depth.astype(proj.dtype))
    background = settings.background if under is None else (0.0, 0.0, 0.0)
    if options.order is Order.PER_PIXEL and extra is not None:
        raise SplatglError(PER_PIXEL_LAYERS_REFUSED)
    raster = rasterize(proj, values, ranges, background, options, progress=progress, layers=extra)
    color, alpha, depth = raster.color, raster.alpha, raster.depth
    if under is not None:
        rgba = composite_under(color, alpha, under, settings.background)
        depth = composite_depth(depth, alpha, under).astype(proj.dtype)
        color, alpha = rgba[..., :3].astype(proj.dtype), rgba[..., 3].astype(proj.dtype)
    return ReferenceImage(color=color, alpha=alpha, depth=depth,
                          transmittance=raster.transmittance, n_contrib=raster.n_contrib,
                          projected=proj, sorted_values=values, ranges=ranges, options=options,
                          n_blended=raster.n_blended, layers=raster.layers or None)


def with_settings(options: ReferenceOptions, settings: RenderSettings) -> ReferenceOptions:
    """``options`` with the reference's parts of ``settings`` (:class:`RenderSettings`): its
    emulation knobs (unless ``options`` brings its own) and its order."""
    changes = {}
    if not settings.emulation.is_default and options.emulation.is_default:
        changes["emulation"] = settings.emulation
    if settings.order is Order.PER_PIXEL:
        changes["order"] = Order.PER_PIXEL
    return dataclasses.replace(options, **changes) if changes else options
