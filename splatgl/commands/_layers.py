"""``--layers``, ``--normal-space`` and ``--under`` options (render, its ``--path``, eval)."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..cameras.camera import Camera
from ..errors import SplatglError
from ..imagefiles.layer_files import LayerFiles
from ..output.layers import Layer, NormalSpace, parse_layer_names
from ..imagefiles.under_exr import read_under
from ..output.under import DepthKind, UnderImage

#: ``--under-channel``'s default: the depth channel splatgl writes.
DEFAULT_CHANNEL = "Z"

LAYER_NAMES = ", ".join(m.value for m in Layer)


def add_layer_arguments(p: argparse.ArgumentParser, under: bool = True) -> None:
    g = p.add_argument_group("layers (docs/layers.md)")
    g.add_argument("--layers", default=None, metavar="LIST",
                   help=f"layers to write, comma-separated: {LAYER_NAMES}. An .exr gets one "
                        "file with a channel per layer (Z, median.Z, N.X/N.Y/N.Z, count, id); a "
                        ".png or .tif the colour and beside it a colourised picture of each other "
                        "layer with its scale, NAME_LAYER.png (default: an .exr holds colour, "
                        "alpha and depth, a .png colour)")
    g.add_argument("--normal-space", choices=[m.value for m in NormalSpace], default="camera",
                   help="normals in camera axes (x right, y down, z forward; default) or world axes")
    if under:
        g.add_argument("--under", type=Path, default=None, metavar="FILE.exr",
                       help="composite the splats into this render of opaque geometry from the same "
                            "camera (R, G, B, optionally A, and a depth channel Z): splats at or "
                            "behind its depth are dropped, the rest drawn over its colour")
        g.add_argument("--under-depth", choices=[m.value for m in DepthKind], default=None,
                       help="what --under's Z holds: view-space z or distance along the ray "
                            "(default: the file's splatgl:depth attribute; one of them must say)")
        g.add_argument("--under-channel", default=None, metavar="NAME",
                       help="--under's depth channel (default Z)")


def named_layers(args: argparse.Namespace) -> tuple[Layer, ...]:
    """The layers ``--layers`` names (empty without it)."""
    return parse_layer_names(args.layers) if args.layers is not None else ()


def layer_files(args: argparse.Namespace, camera: Camera | None) -> LayerFiles:
    """How the layers go to files: ``--layers``, ``--normal-space`` and the camera (its pose
    for world normals; its model's depth metric for the files' ``splatgl:depth``)."""
    space = NormalSpace(args.normal_space)
    named = named_layers(args)
    if space is NormalSpace.WORLD and Layer.NORMAL not in named:
        raise SplatglError("--normal-space world applies to the normal layer; add normal to --layers")
    lens = camera is not None and camera.model.depth_is_distance
    return LayerFiles(named, space,
                      camera.world_to_camera if camera is not None and space is NormalSpace.WORLD else None,
                      DepthKind.DISTANCE if lens else DepthKind.Z)


def check_under_options(args: argparse.Namespace) -> None:
    """``--under-depth`` / ``--under-channel`` need ``--under`` (``--under-channel Z``, its
    default, too: given, it is refused rather than ignored)."""
    if getattr(args, "under", None) is None:
        given = [o for o, v in (("--under-depth", getattr(args, "under_depth", None)),
                                ("--under-channel", getattr(args, "under_channel", None)))
                 if v is not None]
        if given:
            verb = "describes" if len(given) == 1 else "describe"
            raise SplatglError(f"{' and '.join(given)} {verb} the --under file; give --under "
                               "FILE.exr")


def under_from_args(args: argparse.Namespace) -> UnderImage | None:
    """The geometry ``--under`` names (read and checked before any rendering), or None."""
    check_under_options(args)
    if getattr(args, "under", None) is None:
        return None
    return read_under(args.under, args.under_depth, args.under_channel or DEFAULT_CHANNEL)
