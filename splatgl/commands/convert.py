"""``splatgl convert IN OUT``: rewrite a scene in another format and report the round-trip error."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from ..convert import convert

NAME = "convert"
ORDER = 25
HELP = "convert a scene to another format (.ply, .splat) and report the round-trip error"
DESCRIPTION = """Read a scene in any supported format and write it in the format OUT's extension
names (.ply: float32, exact; .splat: 8-bit colour, opacity and rotation, SH degree 0 only).
OUT is written atomically and never replaced without --force.  Afterwards OUT is read back
and compared with the input, per attribute (max and mean absolute error): position (world
units), scale (relative), opacity, rotation (degrees; q and -q are the same rotation), SH DC
colour (0-1 colour units) and the higher SH bands kept.

examples:
  splatgl convert scene.compressed.ply scene.ply
  splatgl convert scene.ply scene.splat --json
  splatgl convert scene.ply small.ply --sh-degree 1 --force"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", type=Path, help="scene file to read (.ply, .compressed.ply, .spz, "
                                            ".ksplat, .splat)")
    p.add_argument("output", type=Path, help="file to write; its extension picks the format")
    p.add_argument("--drop-invalid", action="store_true",
                   help="drop rows with NaN/Inf values or zero quaternions (with a warning that "
                        "counts them) instead of rejecting the input")
    p.add_argument("--sh-degree", type=int, default=None, choices=range(4), metavar="N",
                   help="write SH bands up to degree N only (0-3; default: all the input has)")
    p.add_argument("--force", action="store_true", help="replace OUT if it exists")
    p.add_argument("--json", action="store_true", help="print the result as one JSON object")


def _row(label: str, stats: dict | None, unit: str, fmt: str = ".3g") -> str:
    if stats is None:
        return f"  {label:<12} -"
    return f"  {label:<12} {stats['max']:{fmt}} / {stats['mean']:{fmt}} {unit}"


def run(args: argparse.Namespace) -> int:
    result = convert(args.input, args.output, drop_invalid=args.drop_invalid,
                     sh_degree=args.sh_degree, force=args.force)
    if args.json:
        print(json.dumps(result.as_dict()))
        return 0
    e = result.error
    print(f"wrote {result.output} ({result.output_format}, {result.output_bytes:,} bytes): "
          f"{result.count:,} splats, SH degree {result.sh_degree_out} "
          f"(input: {result.source_format}, SH degree {result.sh_degree_in}) "
          f"in {result.seconds:.2f} s")
    if e["bit_exact"]:
        print("round trip: bit-exact (every stored value identical)")
        return 0
    print("round-trip error, max / mean:")
    print(_row("position", e["position"], "world units"))
    print(_row("scale", e["scale"], "(relative)"))
    print(_row("opacity", e["opacity"], ""))
    print(_row("rotation", e["rotation"], "degrees"))
    print(_row("colour (DC)", e["color"], "(0-1 colour units; 1/255 = 0.00392)"))
    if e["color_outside_01"] and result.output_format == "splat":
        print(f"  ({e['color_outside_01']:,} input colour channels lie outside 0-1 and were "
              "clipped to 8 bits)")
    if result.sh_degree_in > 0:
        kept = "dropped" if result.sh_degree_out == 0 else f"degrees 1-{result.sh_degree_out}"
        print(_row("SH rest", e["sh_rest"], f"({kept})") if e["sh_rest"] else
              f"  SH rest      {kept}")
    return 0
