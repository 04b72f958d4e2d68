"""``splatgl info SCENE``: what is in a scene file (count, SH degree, bounds, value ranges)."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..formats import detect_format, load_scene
from ..info import format_info, scene_info
from ._json_output import add_json_argument, check_json_target, emit_json, json_to_stdout

NAME = "info"
HELP = "print a scene's splat count, SH degree, bounds and value ranges"
DESCRIPTION = (
    "Load a scene file (format detected from its content, else its extension), validate every\n"
    "row, and print its statistics: count, kind, SH degree, bounds (full and 1-99 percentile),\n"
    "opacity, scale and anisotropy ranges.  Bad input exits with status 2 and one line naming\n"
    "the file and the field."
)
ORDER = 20


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scene", type=Path, help="scene file (.ply, .splat, ...)")
    add_json_argument(parser, "the statistics")
    parser.add_argument("--drop-invalid", action="store_true",
                        help="drop rows holding NaN/Inf or degenerate quaternions (with a "
                             "warning) instead of rejecting the file")


def run(args: argparse.Namespace) -> int:
    check_json_target(args, {"SCENE": args.scene})
    scene = load_scene(args.scene, drop_invalid=args.drop_invalid)
    info = {"format": detect_format(args.scene).NAME, **scene_info(scene)}
    if not json_to_stdout(args):
        print(format_info(args.scene, scene, info))
    if args.json is not None:
        emit_json(args, {"path": str(args.scene), **info}, indent=2)
    return 0
