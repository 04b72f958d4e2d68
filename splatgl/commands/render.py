"""``splatgl render``: render one view to an image file."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..image_io import write_image
from ..render import Renderer, render_reference_rgba
from ..settings import RendererKind
from ._common import (add_camera_arguments, add_scene_arguments, add_settings_arguments,
                      camera_from_args, load_scene_arg, settings_from_args)

NAME = "render"
ORDER = 10
HELP = "render a scene (default: the bundled demo) to PNG, TIFF or EXR"
DESCRIPTION = """Render one view of a Gaussian-splat scene headlessly (EGL, or OSMesa).

The output format follows the extension: .png and .tif/.tiff get RGB with the background
composited (8-bit, or 16-bit with --bit-depth 16); .exr gets float R, G, B and A.

examples:
  splatgl render -o demo.png
  splatgl render scene.ply --camera cameras.json --camera-index 3 -o view.exr
  splatgl render scene.ply --width 1920 --height 1080 --background 1,1,1 -o white.png"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_scene_arguments(p)
    p.add_argument("-o", "--output", type=Path, required=True, help="output image (.png, .tif, .exr)")
    p.add_argument("--bit-depth", type=int, choices=(8, 16), default=8,
                   help="bits per channel of PNG/TIFF output (default 8)")
    p.add_argument("--renderer", choices=[k.value for k in RendererKind], default="quad",
                   help="quad = the OpenGL quad path (default); tile = the per-tile compute-shader "
                        "renderer; reference = the NumPy per-tile reference (slow)")
    p.add_argument("--timings", action="store_true", help="print the frame's stage times")
    add_camera_arguments(p)
    add_settings_arguments(p)


def run(args: argparse.Namespace) -> int:
    scene = load_scene_arg(args)
    camera = camera_from_args(args, scene)
    settings = settings_from_args(args)
    kind = RendererKind(args.renderer)
    if kind is RendererKind.REFERENCE:
        rgba = render_reference_rgba(scene, camera, settings)
        times = None
    else:
        with Renderer() as renderer:
            rgba = renderer.render(scene, camera, settings, kind)
            times = getattr(renderer.renderer_for(scene, settings, kind), "last_times", None)
    write_image(args.output, rgba, args.bit_depth)
    print(f"wrote {args.output} ({camera.width}x{camera.height}, {scene.count} splats, {kind.value})")
    if args.timings and times is not None:
        parts = ", ".join(f"{k} {v * 1e3:.1f} ms" for k, v in vars(times).items())
        print(f"timings: {parts}", file=sys.stdout)
    return 0
