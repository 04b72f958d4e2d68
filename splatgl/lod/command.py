"""``splatgl render --lod-threshold/--lod-budget/--lod-blend``: views of a ``.lod.ply`` through
the cut, one view or every frame of a ``--path`` (in this process, ``--workers`` processes or
Ray tasks: each frame is the one-view render of its camera, bit for bit)."""

from __future__ import annotations

import argparse
from types import SimpleNamespace
from typing import Iterable, Iterator

from ..cameras.camera import Camera
from ..errors import SplatglError
from ..gl.context import create_headless_context, make_current, renderer_name
from ..output.layers import BASE, Layer, RenderOutput
from ..model.settings import RenderSettings
from ..cameras.view import View
from .build import LodTree
from .io import is_lod_file, read_lod
from .render import LodSettings
from ..renderers.quad import QuadRenderer
from .source import lod_renderer
from .cut import DEFAULT_BAND, DEFAULT_THRESHOLD_PX


def lod_settings_from_args(args: argparse.Namespace) -> LodSettings | None:
    """The cut ``--lod-threshold/--lod-budget/--lod-blend`` ask for (None: no option given),
    checked before any work: the quad renderer, a ``.lod.ply`` scene, valid values."""
    if all(getattr(args, name, None) is None for name in ("lod_threshold", "lod_budget", "lod_blend")):
        return None
    if args.renderer != "quad":
        raise SplatglError(f"--lod-threshold/--lod-budget render through the quad path, not "
                           f"--renderer {args.renderer}")
    if args.scene is None or not is_lod_file(args.scene):
        raise SplatglError(f"{args.scene}: not a level-of-detail file; build one with "
                           "'splatgl lod SCENE -o SCENE.lod.ply'")
    return LodSettings(args.lod_threshold if args.lod_threshold is not None else DEFAULT_THRESHOLD_PX,
                       args.lod_budget, args.lod_blend if args.lod_blend is not None else DEFAULT_BAND)


class LodFrames:
    """Views of a LOD tree through the cut, with the interface :func:`splatgl.tasks.batch.render_frames`
    renders with (``render_many``, ``renderer_for``); owns its context (use as a context manager).

    Every view chooses its cut alone: the renderer's memory of views close enough to draw the
    leaves (:attr:`splatgl.lod.source.LodOrder.skip_within`, a speed-up for interactive paths) is cleared
    before each, so frame k of a path is the one-view render of camera k whatever came before
    it (another chunk in another worker, or nothing).
    """

    def __init__(self, tree: LodTree, settings: RenderSettings, lod: LodSettings):
        self.settings = settings
        self.nodes = tree.nodes
        self.ctx = create_headless_context()
        try:
            self.renderer = lod_renderer(self.ctx, tree, settings, lod)
        except BaseException:
            self.ctx.release()
            raise

    def render_view(self, camera: Camera, layers: frozenset[Layer] = BASE) -> RenderOutput:
        make_current(self.ctx)
        self.renderer.rows.skip_within = None
        return self.renderer.render(View.of(camera, self.settings, self.nodes), layers)

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


def render_lod(args: argparse.Namespace, settings: RenderSettings, camera: Camera,
               layers: frozenset[Layer]) -> tuple[RenderOutput, SimpleNamespace, str]:
    """Render ``args.scene`` (a .lod.ply) with the cut ``args`` asks for: (layers, times with
    ``cut_nodes`` and ``cut`` (seconds) beside the quad path's stage times, the GL renderer's
    name)."""
    lod = lod_settings_from_args(args)
    with LodFrames(read_lod(args.scene), settings, lod) as frames:
        gl_name = renderer_name(frames.ctx)
        out = frames.render_view(camera, layers)
        renderer, cut = frames.renderer, frames.renderer.rows
        times = SimpleNamespace(**vars(renderer.last_times), cut_nodes=cut.last_cut_nodes,
                                cut=cut.last_cut_s, threshold=f"{cut.last_threshold_px:.2f} px")
    return out, times, gl_name
