"""Views of a level-of-detail tree (a ``.lod.ply`` from ``splatgl lod``) through the cut: one
view (:func:`render_lod`) or the frames of a camera path (:class:`LodFrames`, in this process,
worker processes or Ray tasks: each frame is the one-view render of its camera, bit for bit).
``splatgl render --lod-threshold/--lod-budget/--lod-blend`` maps its options onto these."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Iterable, Iterator

from ..cameras.camera import Camera
from ..gl.context import create_headless_context, make_current, renderer_name
from ..output.layers import BASE, Layer, RenderOutput
from ..output.under import UnderImage
from ..scene.settings import RenderSettings
from ..cameras.view import View
from .build import LodTree
from .selection import LodSettings
from ..renderers.quad import QuadRenderer
from .source import lod_renderer


class LodFrames:
    """Views of a LOD tree through the cut, with the interface :func:`splatgl.tasks.batch.render_frames`
    renders with (``render_many``, ``renderer_for``); owns its context (use as a context manager).

    Every view chooses its cut alone: the renderer's memory of views close enough to draw the
    leaves (:attr:`splatgl.lod.source.LodOrder.skip_within`, a speed-up for interactive paths) is cleared
    before each, so frame k of a path is the one-view render of camera k whatever came before
    it (another chunk in another worker, or nothing).  It draws through the quad path (whose
    rules refuse ``convention`` gsplat) and not in stereo (:attr:`stereo_refusal`).
    """

    #: Why :class:`splatgl.renderers.stereo.StereoRenderer` cannot wrap it (no per-eye views yet).
    stereo_refusal = "--stereo and --lod-threshold/--lod-budget/--lod-blend cannot be combined yet"

    def __init__(self, tree: LodTree, settings: RenderSettings, lod: LodSettings):
        self.settings = settings
        self.nodes = tree.nodes
        self.ctx = create_headless_context()
        try:
            self.renderer = lod_renderer(self.ctx, tree, settings, lod)
        except BaseException:
            self.ctx.release()
            raise

    def render_view(self, camera: Camera, layers: frozenset[Layer] = BASE,
                    under: UnderImage | None = None) -> RenderOutput:
        """One view's ``layers`` (composited into ``under`` if given; the top contributor is
        a node of the tree)."""
        make_current(self.ctx)
        self.renderer.rows.skip_within = None
        view = View.of(camera, self.settings, self.nodes)
        if under is None:
            return self.renderer.render(view, layers)
        return self.renderer.render(view, layers, under=view.geometry(under))

    def render_many(self, scene, cameras: Iterable[Camera], settings=None, kind=None,
                    layers: frozenset[Layer] | None = None) -> Iterator:
        """Frames of ``cameras`` (``scene``, ``settings`` and ``kind`` are the tree's, given at
        construction): (H, W, 4) arrays, or :class:`RenderOutput` with ``layers``."""
        for camera in cameras:
            out = self.render_view(camera, BASE if layers is None else layers)
            yield out.rgba if layers is None else out

    def renderer_for(self, scene=None, settings=None, kind=None) -> QuadRenderer:
        return self.renderer

    def close(self) -> None:
        if self.ctx is not None:
            make_current(self.ctx)
            self.renderer.release()
            self.ctx.release()
            self.ctx = None

    def __enter__(self) -> "LodFrames":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def render_lod(tree: LodTree, camera: Camera, settings: RenderSettings = RenderSettings(),
               lod: LodSettings = LodSettings(), layers: frozenset[Layer] = BASE,
               under: UnderImage | None = None) -> tuple[RenderOutput, SimpleNamespace, str]:
    """One view of ``tree`` (:func:`splatgl.lod.io.read_lod`) through the cut ``lod`` chooses:
    (the ``layers``, times with ``cut_nodes`` and ``cut`` (seconds) beside the quad path's
    stage times, the GL renderer's name), on a context of its own."""
    with LodFrames(tree, settings, lod) as frames:
        gl_name = renderer_name(frames.ctx)
        out = frames.render_view(camera, layers, under)
        renderer, cut = frames.renderer, frames.renderer.rows
        times = SimpleNamespace(**vars(renderer.last_times), cut_nodes=cut.last_cut_nodes,
                                cut=cut.last_cut_s, threshold=f"{cut.last_threshold_px:.2f} px")
    return out, times, gl_name
