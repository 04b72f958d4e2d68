"""``splatgl path``: generate a camera path and write it as a file to edit and render."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..cameras.up import UP_CHOICES, resolve_up
from ..datasets import load_cameras
from ..datasets.gs_cameras import gs_cameras_json
from ..datasets.nerfstudio_path import camera_path_json
from ..datasets.named_camera import NamedCamera
from ..errors import SplatglError
from ..paths import ellipse, interpolate, orbit, path_json, spiral
from ..paths.keyframes import write_path
from ._common import add_scene_arguments, load_scene_arg, positive_float, positive_int
from ._outputs import add_force_argument, check_output

NAME = "path"
ORDER = 15
HELP = "generate a camera path (orbit, spiral, ellipse, interpolate) as a file"
DESCRIPTION = """Generate a camera path and write it as a file that `splatgl render --path`
reads (and that you can edit).

  orbit        a circle around the scene's robust centre (frame 0 = the default view)
  spiral       the forward-facing spiral of the NeRF/3DGS LLFF videos, through the cameras
  ellipse      an ellipse through the cameras around the point they look at (Mip-NeRF 360)
  interpolate  a smooth path through chosen cameras (Catmull-Rom positions, squad rotations)

The file is splatgl's path format (default; keyframes as look-ats or matrices, one frame per
key for orbit/spiral/ellipse), a nerfstudio camera_path.json (--as nerfstudio), or a 3DGS
cameras.json (--as 3dgs).

examples:
  splatgl path orbit scene.ply --frames 120 --elevation 30 -o orbit.json
  splatgl path ellipse --cameras garden/sparse/0 --frames 240 -o ellipse.json
  splatgl path interpolate --cameras cameras.json --select 0,10,20,30 --frames 300 --loop -o tour.json
  splatgl render scene.ply --path tour.json -o tour.mp4"""

FORMATS = ("splatgl", "nerfstudio", "3dgs")


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="generator", metavar="GENERATOR", required=True)

    def common(q: argparse.ArgumentParser) -> None:
        q.add_argument("-o", "--output", type=Path, required=True, help="path file to write (.json)")
        q.add_argument("--frames", type=positive_int, default=120, help="frames in the path (default 120)")
        q.add_argument("--as", dest="fmt", choices=FORMATS, default="splatgl",
                       help="file format (default splatgl)")
        q.add_argument("--fps", type=positive_float, default=30.0,
                       help="frame rate stored in the file (default 30)")
        add_force_argument(q)

    def cameras(q: argparse.ArgumentParser) -> None:
        q.add_argument("--cameras", required=True, metavar="SOURCE",
                       help="camera source: COLMAP model or dataset folder, transforms.json, cameras.json, ...")
        q.add_argument("--select", default=None, metavar="RANGES",
                       help="only these cameras (start:stop:step and/or indices, comma-separated)")

    o = sub.add_parser("orbit", help="a circle around the scene", formatter_class=argparse.RawDescriptionHelpFormatter)
    add_scene_arguments(o)
    common(o)
    o.add_argument("--elevation", type=float, default=20.0, help="degrees above the horizon (default 20)")
    o.add_argument("--radius", type=float, default=None, help="distance from the centre (default: the framing distance)")
    o.add_argument("--fov", type=float, default=50.0, help="vertical field of view, degrees (default 50)")
    o.add_argument("--width", type=positive_int, default=1280, help="image width (default 1280)")
    o.add_argument("--height", type=positive_int, default=720, help="image height (default 720)")
    o.add_argument("--up", choices=UP_CHOICES, default=None,
                   help="world axis the orbit turns about, up in its images; default as for "
                        "'splatgl render' (the average up of the training cameras found beside "
                        "the scene, else -y), so the file's frames are render --path orbit's")
    s = sub.add_parser("spiral", help="forward-facing spiral through the cameras")
    cameras(s)
    common(s)
    s.add_argument("--rotations", type=float, default=2.0, help="turns of the spiral (default 2)")
    e = sub.add_parser("ellipse", help="ellipse through the cameras around their focus point")
    cameras(e)
    common(e)
    i = sub.add_parser("interpolate", help="smooth path through chosen cameras")
    cameras(i)
    common(i)
    i.add_argument("--loop", action="store_true", help="close the path back to the first camera")


def run(args: argparse.Namespace) -> int:
    if args.output.suffix.lower() != ".json":
        raise SplatglError(f"{args.output}: path files are JSON; name the output *.json")
    check_output(args, args.output, "-o")  # not a file it reads; an existing one with --force
    if args.generator == "orbit":
        scene = load_scene_arg(args)
        if not 0.0 < args.fov < 180.0:
            raise SplatglError(f"--fov must be in (0, 180) degrees, got {args.fov}")
        up, _ = resolve_up(args.up, args.scene)   # as render's default camera and orbit
        cams = orbit(scene, args.frames, args.width, args.height, args.fov, args.elevation,
                     args.radius, tuple(float(v) for v in up))
        lo, hi = scene.robust_bounds
        keys = path_json(cams, look_at_target=0.5 * (lo + hi), fps=args.fps, up=up)
    else:
        source = load_cameras(args.cameras, args.select)
        if args.generator == "spiral":
            cams = spiral(source, args.frames, args.rotations)
        elif args.generator == "ellipse":
            cams = ellipse(source, args.frames)
        else:
            cams = interpolate(source, args.frames, args.loop)
        keys = None
        if args.generator == "interpolate" and args.fmt == "splatgl":
            keys = path_json(source, frames=args.frames, loop=args.loop, fps=args.fps)
        elif args.fmt == "splatgl":
            keys = path_json(cams, fps=args.fps)
    if args.fmt == "splatgl":
        write_path(args.output, keys)
    elif args.fmt == "nerfstudio":
        write_path(args.output, camera_path_json(cams, args.fps))
    else:
        write_path(args.output, gs_cameras_json([NamedCamera(f"frame_{k:05d}", c) for k, c in enumerate(cams)]))
    print(f"wrote {args.output} ({len(cams)} frames, {args.generator}, {args.fmt})")
    return 0
