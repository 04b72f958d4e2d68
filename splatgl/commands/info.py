"""``splatgl info SCENE``: what is in a scene file (count, SH degree, bounds, value ranges)."""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

from ..formats import detect_format, load_scene
from ..lod.io import levels_of
from ..scene.stats import format_info, scene_info
from ._spz_axes import add_spz_axes_argument
from ._json_output import add_json_argument, check_json_target, emit_json, json_to_stdout
from ._memory import add_memory_argument, memory_budget
from ._outputs import add_force_argument

NAME = "info"
HELP = "print a scene's splat count, SH degree, bounds and value ranges"
DESCRIPTION = (
    "Load a scene file (format detected from its content, else its extension), validate every\n"
    "row, and print its statistics: count, kind, SH degree, bounds (full and 1-99 percentile),\n"
    "opacity, scale and anisotropy ranges; for SPZ, which axes the file stores and how that was\n"
    "decided (its SPZ_ADOBE_coordinate_system extension, else --spz-axes, else the version's\n"
    "default).  With --stats, also each attribute `splatgl edit --filter` sees (min, 1st and\n"
    "99th percentiles, median, max, with units) and the estimated overdraw of the default view\n"
    "(fragments per pixel), to choose filter thresholds before editing.  Bad input exits with\n"
    "status 2 and one line naming the file and the field."
)
ORDER = 20


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scene", type=Path, help="scene file (.ply, .splat, ...)")
    add_json_argument(parser, "the statistics")
    add_force_argument(parser)
    parser.add_argument("--drop-invalid", action="store_true",
                        help="drop rows holding NaN/Inf or degenerate quaternions (with a "
                             "warning) instead of rejecting the file")
    parser.add_argument("--stats", action="store_true",
                        help="also per-attribute statistics (min, 1st percentile, median, 99th "
                             "percentile, max of what `splatgl edit --filter` sees) and the "
                             "estimated overdraw of the default view (fragments per pixel)")
    add_memory_argument(parser, "a larger binary PLY is read a block of rows at a time (in "
                                "two or three passes; docs/editing.md)")
    add_spz_axes_argument(parser)


def run(args: argparse.Namespace) -> int:
    check_json_target(args)  # not SCENE, and an existing file only with --force
    if args.spz_axes is None and _streamed(args):
        return 0
    scene = load_scene(args.scene, drop_invalid=args.drop_invalid, spz_axes=args.spz_axes,
                       allow_empty=True)  # what `edit --allow-empty` writes
    info = {"format": detect_format(args.scene).NAME, **scene_info(scene)}
    if info["format"] == "spz":
        from ..formats.spz import read_axes
        with warnings.catch_warnings():  # a conflict with the file was reported on loading
            warnings.simplefilter("ignore")
            info["spz_axes"] = read_axes(args.scene, args.spz_axes).as_dict()
    _add_levels(args.scene, info)
    text = format_info(args.scene, scene, info)
    if args.stats and scene.count:
        from ..edit.statistics import attribute_statistics, format_statistics, overdraw

        info["attributes"] = attribute_statistics(scene)
        info["overdraw"] = overdraw(scene)
        text += "\n" + format_statistics(info["attributes"], info["overdraw"])
    if not json_to_stdout(args):
        print(text)
    if args.json is not None:
        emit_json(args, {"path": str(args.scene), **info}, indent=2)
    return 0


def _streamed(args: argparse.Namespace) -> bool:
    """Report a binary PLY larger than --memory read a block at a time; False to load it."""
    from ..edit.statistics import format_statistics
    from ..edit.streamed_stats import info_streamed

    found = info_streamed(args.scene, memory_budget(args), args.drop_invalid, args.stats)
    if found is None:
        return False
    stats, table, draw = found
    info = {"format": "ply", **stats}
    _add_levels(args.scene, info)
    text = format_info(args.scene, None, info)
    if table is not None:
        info["attributes"], info["overdraw"] = table, draw
        text += "\n" + format_statistics(table, draw)
    if not json_to_stdout(args):
        print(text)
    if args.json is not None:
        emit_json(args, {"path": str(args.scene), **info}, indent=2)
    return True


def _add_levels(path, info: dict) -> None:
    """``info["lod_levels"]`` for a level-of-detail file: splats per level
    (:func:`splatgl.lod.io.levels_of`)."""
    levels = levels_of(path)
    if levels is not None:
        info["lod_levels"] = levels