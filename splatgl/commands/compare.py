"""``splatgl compare``: an approximate renderer against the per-tile reference, same camera."""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

from ..output.pictures import heatmap, side_by_side
from ..output.image_formats import image_format, suffix_list
from ..output.images import write_image
from ..output.files import OutputFiles
from ..progress import default_progress
from ..errors import SplatglError
from ..evaluation.metrics import check_ssim_size, depth_errors, image_errors
from ..api import Renderer
from ..model.settings import Convention, RendererKind
from ._common import (add_camera_arguments, add_scene_arguments, add_settings_arguments,
                      check_convention, check_size, inputs_from_args, positive_float, size_origin)
from ._json_output import add_json_argument, check_json_target, emit_json, json_to_stdout

NAME = "compare"
ORDER = 30
HELP = "compare the quad path (or tile renderer) with the per-tile reference"
DESCRIPTION = """Render one view with two renderers and print how far apart they are.

By default the quad path (global depth sort, instanced quads) is compared with the NumPy
per-tile reference rasterizer (3DGS rules).  Metrics are on RGB with the background
composited: PSNR (peak 1), SSIM, mean and max absolute error, and the share of pixels whose
largest channel error exceeds 1/255 and 4/255.

examples:
  splatgl compare scene.ply
  splatgl compare scene.ply --camera cameras.json --camera-index 2 --json
  splatgl compare scene.ply --json figures.json
  splatgl compare scene.ply --side-by-side both.png --heatmap err.png --heatmap-scale 0.01"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_scene_arguments(p)
    p.add_argument("--renderer", choices=[k.value for k in RendererKind], default="quad",
                   help="the renderer under test (default quad)")
    p.add_argument("--against", choices=[k.value for k in RendererKind], default="reference",
                   help="the renderer taken as truth (default reference)")
    add_json_argument(p, "the figures (one object)")
    p.add_argument("--side-by-side", type=Path, default=None, metavar="FILE",
                   help=f"write both renders next to each other ({suffix_list()})")
    p.add_argument("--heatmap", type=Path, default=None, metavar="FILE",
                   help="write a heat map of the per-pixel error with its colour scale")
    p.add_argument("--heatmap-scale", type=positive_float, default=4.0 / 255.0, metavar="ERR",
                   help="error shown at the top of the heat map's scale (default 4/255)")
    add_camera_arguments(p)
    add_settings_arguments(p)


def run(args: argparse.Namespace) -> int:
    kinds = (RendererKind(args.renderer), RendererKind(args.against))
    check_convention(args, *kinds)
    files = OutputFiles({"--side-by-side": args.side_by_side, "--heatmap": args.heatmap})
    for option, path in files.targets.items():
        image_format(path, option)  # before rendering (x.bmp, or no suffix at all)
    check_json_target(args, {"SCENE": args.scene, "--side-by-side": args.side_by_side,
                             "--heatmap": args.heatmap})
    if args.stereo is not None:
        raise SplatglError("--stereo renders with splatgl render or view; compare measures one view")
    scene, settings, camera = inputs_from_args(args)
    check_ssim_size(camera.width, camera.height, size_origin(args))
    progress = default_progress()
    outputs, seconds = [], []
    with Renderer() as renderer:
        for kind in kinds:
            check_size(args, camera, kind, renderer.ctx)
        for kind in kinds:
            side = settings
            if kind is not RendererKind.REFERENCE:   # the GPU renderers draw the inria rules only
                side = dataclasses.replace(settings, convention=Convention.INRIA)
                renderer.render(scene, camera, side, kind, progress)  # warm-up: compile, upload
            t0 = time.perf_counter()
            outputs.append(renderer.render_layers(scene, camera, side, kind, progress))
            seconds.append(time.perf_counter() - t0)
    images = [o.rgba for o in outputs]
    errors = image_errors(images[0], images[1])
    depth = depth_errors(outputs[0], outputs[1])
    names = tuple(k.value for k in kinds)
    with files:
        if args.side_by_side is not None:
            write_image(files.temp("--side-by-side"), side_by_side(images[0], images[1], names))
        if args.heatmap is not None:
            write_image(files.temp("--heatmap"), heatmap(images[0], images[1], args.heatmap_scale))
    result = {
        "scene": str(args.scene) if args.scene else "demo", "splats": scene.count,
        "width": camera.width, "height": camera.height, "renderer": names[0], "against": names[1],
        **errors.as_dict(), **depth, "seconds": dict(zip(names, seconds)),
    }
    if json_to_stdout(args):
        emit_json(args, result)
        return 0
    psnr = "inf" if errors.psnr == float("inf") else f"{errors.psnr:.2f} dB"
    print(f"{result['scene']}: {scene.count} splats, {camera.width}x{camera.height}, "
          f"{names[0]} against {names[1]}")
    print(f"  PSNR       {psnr}")
    print(f"  SSIM       {errors.ssim:.6f}")
    print(f"  mean |err| {errors.mean_abs:.3e}")
    print(f"  max |err|  {errors.max_abs:.3e}")
    print(f"  > 1/255    {errors.off_1 * 100:.3f} % of pixels")
    print(f"  > 4/255    {errors.off_4 * 100:.3f} % of pixels")
    print(f"  alpha      max |err| {depth['alpha_max_abs']:.3e}")
    print(f"  depth D    max |err| {depth['depth_max_abs']:.3e} = {depth['depth_max_rel'] * 100:.3f} % of "
          f"the farthest expected depth {depth['depth_scale']:.4g}")
    print("  time       " + ", ".join(f"{n} {s * 1e3:.1f} ms" for n, s in zip(names, seconds))
          + " (colour and depth)")
    if args.json is not None:
        emit_json(args, result)
    return 0
