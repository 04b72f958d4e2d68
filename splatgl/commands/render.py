"""``splatgl render``: render one view to an image file."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from contextlib import nullcontext

from ..errors import SplatglError
from ..image_io import write_image
from ..output import RenderOutput
from ..pictures import depth_preview
from ..render import Renderer, render_reference_layers
from ..settings import RendererKind
from ..stereo import StereoLayout, combine, eye_cameras
from ._common import (add_camera_arguments, add_scene_arguments, add_settings_arguments,
                      inputs_from_args)

NAME = "render"
ORDER = 10
HELP = "render a scene (default: the bundled demo) to PNG, TIFF or EXR"
DESCRIPTION = """Render one view of a Gaussian-splat scene headlessly (EGL, or OSMesa).

The output format follows the extension: .png and .tif/.tiff get RGB with the background
composited (8-bit, or 16-bit with --bit-depth 16); .exr gets float R, G, B, A and Z, where Z
is the expected depth D / A (camera-space z, world units; 0 where nothing was drawn) and
D = sum z alpha T is accumulated with the colour's weights in the same pass.

examples:
  splatgl render -o demo.png
  splatgl render scene.ply --camera cameras.json --camera-index 3 -o view.exr
  splatgl render scene.ply --width 1920 --height 1080 --background 1,1,1 -o white.png
  splatgl render scene.ply -o view.png --depth-png depth.png
  splatgl render scene.ply --projection fisheye --fov 200 --width 1024 --height 1024 -o fish.png
  splatgl render scene.ply --projection equirectangular --width 2048 --height 1024 -o pano.png
  splatgl render scene.ply --projection equirectangular --stereo 0.065 --stereo-layout top-bottom \
      --width 2048 --height 1024 -o ods.png"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_scene_arguments(p)
    p.add_argument("-o", "--output", type=Path, required=True, help="output image (.png, .tif, .exr)")
    p.add_argument("--bit-depth", type=int, choices=(8, 16), default=8,
                   help="bits per channel of PNG/TIFF output (default 8)")
    p.add_argument("--renderer", choices=[k.value for k in RendererKind], default="quad",
                   help="quad = the OpenGL quad path (default); tile = the per-tile compute-shader "
                        "renderer; reference = the NumPy per-tile reference (slow)")
    p.add_argument("--depth-png", type=Path, default=None, metavar="FILE",
                   help="also write a colourised preview of the expected depth with a scale bar")
    p.add_argument("--timings", action="store_true", help="print the frame's stage times")
    add_camera_arguments(p)
    add_settings_arguments(p)


def run(args: argparse.Namespace) -> int:
    scene, settings, camera = inputs_from_args(args)
    kind = RendererKind(args.renderer)
    want_depth = args.depth_png is not None or args.output.suffix.lower() == ".exr"
    if args.depth_png is not None and args.depth_png.suffix.lower() not in (".png", ".tif", ".tiff"):
        raise SplatglError(f"{args.depth_png}: --depth-png needs a .png or .tif file name")
    times = None
    with Renderer() if kind is not RendererKind.REFERENCE else nullcontext() as renderer:
        def view(cam):
            if renderer is None:
                return render_reference_layers(scene, cam, settings)
            if want_depth:
                return renderer.render_layers(scene, cam, settings, kind)
            return RenderOutput(renderer.render(scene, cam, settings, kind), None)

        if args.stereo is not None:
            eyes = [view(cam) for cam in eye_cameras(camera, args.stereo)]
        else:
            out = view(camera)
        if renderer is not None:
            times = getattr(renderer.renderer_for(scene, settings, kind), "last_times", None)
    if args.stereo is not None:
        layout = StereoLayout(args.stereo_layout)
        if layout is StereoLayout.SEPARATE:
            for eye, name in zip(eyes, ("left", "right")):
                path = args.output.with_name(f"{args.output.stem}_{name}{args.output.suffix}")
                write_image(path, eye.rgba, args.bit_depth,
                            depth=eye.expected_depth() if want_depth else None)
                print(f"wrote {path} ({name} eye)")
            return 0
        out = combine(eyes[0], eyes[1], layout)
    depth = out.expected_depth() if want_depth else None
    write_image(args.output, out.rgba, args.bit_depth, depth=depth)
    if args.depth_png is not None:
        write_image(args.depth_png, depth_preview(depth, out.alpha))
        print(f"wrote {args.depth_png} (expected depth)")
    print(f"wrote {args.output} ({camera.width}x{camera.height}, {scene.count} splats, {kind.value})")
    if args.timings and times is not None:
        parts = ", ".join(f"{k} {v * 1e3:.1f} ms" for k, v in vars(times).items())
        print(f"timings: {parts}", file=sys.stdout)
    return 0
