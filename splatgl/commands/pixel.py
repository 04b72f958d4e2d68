"""``splatgl pixel``: the splats that make one pixel, front to back, from the reference."""

from __future__ import annotations

import argparse

from ..errors import SplatglError
from ..scene.settings import RendererKind
from ..reference.pixel import check_pixel, pixel_splats
from ._common import (add_camera_arguments, add_scene_arguments, add_settings_arguments,
                      camera_from_args, check_convention, default_size, load_scene_arg, projection_from_args,
                      settings_from_args)
from ._json_output import add_json_argument, check_json_target, emit_json, json_to_stdout
from ._outputs import add_force_argument
from ._layers import under_from_args

NAME = "pixel"
ORDER = 17
HELP = "list the splats that blend into one pixel, front to back (from the reference)"
DESCRIPTION = """List the splats that blend into pixel X,Y (column, row from the top-left, from 0)
of a view, front to back, as the NumPy per-tile reference blends them: each splat's index in the
scene (its row, counted from 0 after --drop-invalid), its depth (view z; a fisheye's or
panorama's distance; a 2DGS surfel's hit; with --order per-pixel the depth of its peak along
the pixel's ray), its alpha at the pixel centre, its weight alpha T and the transmittance T
after it.  The weights sum to the pixel's alpha, and the listed colours with their weights make
its colour: the pixel splatgl render --renderer reference draws with the same options
(--order per-pixel and --emulate included: the listing follows their order and rules).  It is
how to find the index of a floater (the splat with the largest weight, the top-id layer of
splatgl render --layers) to delete it: splatgl edit scene.ply -o clean.ply --remove
'index == 123' (with the same --drop-invalid).

examples:
  splatgl pixel scene.ply --camera cam.json --at 640,360
  splatgl pixel scene.ply --at 100,200 --width 640 --height 360 --json - | jq '.splats[0]'
  splatgl pixel scene.ply --camera cam.json --at 640,360 --under mesh.exr"""


def parse_at(text: str) -> tuple[int, int]:
    """``X,Y`` as two whole numbers."""
    try:
        x, y = (int(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected X,Y (two whole numbers), got {text!r}") from None
    return x, y


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_scene_arguments(p)
    p.add_argument("--at", type=parse_at, required=True, metavar="X,Y",
                   help="the pixel: column X and row Y, from 0 at the top-left")
    p.add_argument("--limit", type=int, default=50, metavar="N",
                   help="list at most N splats in the text (default 50; 0: all; --json lists all)")
    add_json_argument(p, "the listing")
    add_force_argument(p)
    g = p.add_argument_group("geometry")
    g.add_argument("--under", default=None, metavar="FILE.exr",
                   help="leave out the splats at or behind this geometry's depth (as render --under)")
    g.add_argument("--under-depth", choices=("z", "distance"), default=None,
                   help="what --under's depth holds (default: the file's splatgl:depth)")
    g.add_argument("--under-channel", default=None, metavar="NAME",
                   help="--under's depth channel (default Z)")
    add_camera_arguments(p)
    add_settings_arguments(p)


def run(args: argparse.Namespace) -> int:
    if args.limit < 0:
        raise SplatglError(f"--limit must be 0 or more, got {args.limit}")
    if args.stereo is not None:
        raise SplatglError("--stereo: pixel lists one camera's pixel; give the eye's camera")
    check_json_target(args)  # not SCENE, --camera, --transform, --under; existing: --force
    check_convention(args, RendererKind.REFERENCE,
                     advice="pixel explains the NumPy reference's image; leave {option} out")
    settings = settings_from_args(args)
    camera = camera_from_args(args, None, settings)   # the camera file checked early
    size = ((camera.width, camera.height) if camera is not None
            else default_size(args, projection_from_args(args)))
    x, y = args.at
    check_pixel(x, y, *size)
    under = under_from_args(args)
    scene = load_scene_arg(args)
    camera = camera_from_args(args, scene, settings)
    geometry = None
    if under is not None:
        from ..cameras.view import View
        geometry = View.of(camera, settings, scene).geometry(under)
    listing = pixel_splats(scene, camera, x, y, settings, settings.convention, geometry)
    if not json_to_stdout(args):
        print(listing.table(args.limit or None))
    if args.json is not None:
        emit_json(args, {"scene": str(args.scene) if args.scene else None,
                         "width": camera.width, "height": camera.height, **listing.to_json()},
                  indent=2)
    return 0
