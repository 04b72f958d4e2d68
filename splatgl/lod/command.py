"""``splatgl render --lod-threshold/--lod-budget/--lod-blend``: one view of a ``.lod.ply`` through the cut."""

from __future__ import annotations

import argparse
from types import SimpleNamespace

from ..camera import Camera
from ..errors import SplatglError
from ..gl.context import create_headless_context, renderer_name
from ..output import RenderOutput
from ..settings import RenderSettings
from ..transform import apply_model
from .io import is_lod_file, read_lod
from .render import LodRenderer, LodSettings
from .cut import DEFAULT_BAND, DEFAULT_THRESHOLD_PX


def render_lod(args: argparse.Namespace, settings: RenderSettings, camera: Camera,
               want_depth: bool) -> tuple[RenderOutput, SimpleNamespace, str]:
    """Render ``args.scene`` (a .lod.ply) with the cut ``args`` asks for: (layers, times with
    ``cut_nodes`` and ``cut`` (seconds) beside the quad path's stage times, the GL renderer's
    name)."""
    if args.renderer != "quad":
        raise SplatglError(f"--lod-threshold/--lod-budget render through the quad path, not "
                           f"--renderer {args.renderer}")
    if args.scene is None or not is_lod_file(args.scene):
        raise SplatglError(f"{args.scene}: not a level-of-detail file; build one with "
                           "'splatgl lod SCENE -o SCENE.lod.ply'")
    lod = LodSettings(args.lod_threshold if args.lod_threshold is not None else DEFAULT_THRESHOLD_PX,
                      args.lod_budget, args.lod_blend if args.lod_blend is not None else DEFAULT_BAND)
    tree = read_lod(args.scene)
    ctx = create_headless_context()
    gl_name = renderer_name(ctx)
    renderer = LodRenderer(ctx, tree, settings, lod)
    try:
        out = renderer.render_layers(apply_model(camera, settings.model), depth=want_depth)
        times = SimpleNamespace(**vars(renderer.last_times), cut_nodes=renderer.last_cut_nodes,
                                cut=renderer.last_cut_s,
                                threshold=f"{renderer.last_threshold_px:.2f} px")
    finally:
        renderer.release()
        ctx.release()
    return out, times, gl_name
