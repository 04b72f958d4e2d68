"""``splatgl convert IN OUT``: rewrite a scene in another format and report the round-trip error."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..edit.streamed_convert import convert_file
from ..formats.convert import dropped_note
from ..errors import SplatglError
from ._spz_axes import add_spz_axes_argument
from ._json_output import add_json_argument, check_json_target, emit_json, json_to_stdout
from ._memory import add_memory_argument, memory_budget
from ._outputs import add_force_argument

NAME = "convert"
ORDER = 25
HELP = ("convert a scene to another format (.ply, .compressed.ply, .spz, .sog, meta.json, .glb, "
        ".gltf, .splat) and report the round-trip error")
DESCRIPTION = """Read a scene in any supported format and write it in the format OUT's extension
names:
  .ply              float32, exact
  .compressed.ply   PlayCanvas chunks: 11-10-11-bit position and log-scale per 256 splats,
                    10-bit smallest-three rotation, 8-bit colour and opacity, 8-bit SH
  .spz              Niantic SPZ v3 (or --spz-version 2), gzip: 24-bit fixed-point position,
                    8-bit colour, opacity, log-scale and SH; RUB axes, or --spz-axes rdf
  .sog / meta.json  PlayCanvas SOG v2 (zip bundle / folder of lossless WebP): 16-bit log
                    position, 256-entry codebooks, 8-bit rotation, k-means SH palette
  .glb / .gltf      glTF 2.0 with KHR_gaussian_splatting, float32 (glTF axes: y up)
  .splat            8-bit colour, opacity and rotation, SH degree 0 only
OUT is written atomically and never replaced without --force.  Afterwards OUT is read back
and compared with the input, per attribute (max and mean absolute error): position (world
units), scale (relative), opacity, rotation (degrees; q and -q are the same rotation), SH DC
colour (0-1 colour units) and the higher SH bands kept.  For lossy formats each line also
shows the bound the format's quantisation implies for this scene (values outside a format's
fixed range are clipped, and the bound includes the distance clipped); "!" marks a bound
exceeded, which would be a bug.  SOG's SH palette has no a-priori bound (k-means).
SPZ axes: a file's SPZ_ADOBE_coordinate_system extension says which axes it stores; where it
has none, versions 3-4 are RUB (the SPZ specification) and versions 1-2 as stored, unless
--spz-axes says otherwise (splat-transform 3.x writes PLY's RDF unconverted: --spz-axes rdf).
--spz-axes applies to each .spz side: how an input without the extension is read, and which
axes the output stores (rdf, and version 2, are recorded with the extension).  The axes each
SPZ file was read with are printed.

examples:
  splatgl convert scene.compressed.ply scene.ply
  splatgl convert scene.ply scene.sog
  splatgl convert scene.ply scene.spz --spz-version 2
  splatgl convert from-splat-transform-3.spz scene.ply --spz-axes rdf
  splatgl convert scene.ply scene.splat --json
  splatgl convert scene.ply scene.spz --json report.json
  splatgl convert scene.ply small.ply --sh-degree 1 --force"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", type=Path, help="scene file to read (.ply, .compressed.ply, .spz, "
                                            ".sog, meta.json, .glb, .gltf, .ksplat, .splat)")
    p.add_argument("output", type=Path, help="file to write; its extension picks the format")
    p.add_argument("--drop-invalid", action="store_true",
                   help="drop rows with NaN/Inf values or zero quaternions (with a warning that "
                        "counts them) instead of rejecting the input")
    p.add_argument("--sh-degree", type=int, default=None, choices=range(4), metavar="N",
                   help="write SH bands up to degree N only (0-3; default: all the input has)")
    add_force_argument(p)
    p.add_argument("--spz-version", type=int, choices=(2, 3), default=None, metavar="V",
                   help="SPZ version to write for .spz output: 3 (default; smallest-three "
                        "rotations, RUB axes) or 2 (3-byte rotations)")
    add_spz_axes_argument(p, "for .spz files that record none: rub (the SPZ specification; "
                             "default for versions 3-4) or rdf (PLY axes as is; splat-transform "
                             "3.x); for .spz output, the axes written (default rub for version 3)")
    add_memory_argument(p, "a larger binary PLY written as .ply, .splat or "
                        ".compressed.ply is converted a block at a time (other outputs are "
                        "refused)")
    add_json_argument(p, "the result (one object)")


def _row(label: str, stats: dict | None, unit: str, bound: float | None = None,
         fmt: str = ".3g") -> str:
    if stats is None:
        return f"  {label:<12} -"
    text = f"  {label:<12} {stats['max']:{fmt}} / {stats['mean']:{fmt}}"
    if bound is not None:
        mark = "" if stats["max"] <= bound else " !"
        text += f" (bound {bound:{fmt}}{mark})"
    return f"{text} {unit}"


def run(args: argparse.Namespace) -> int:
    options = {}
    if args.spz_version is not None:
        if not args.output.name.lower().endswith(".spz"):
            raise SplatglError(f"{args.output}: --spz-version applies to .spz output only")
        options["version"] = args.spz_version
    check_json_target(args, {"OUT": args.output})  # nor IN; an existing file only with --force
    result = convert_file(args.input, args.output, drop_invalid=args.drop_invalid,
                          sh_degree=args.sh_degree, force=args.force, spz_axes=args.spz_axes,
                          memory=memory_budget(args), **options)
    if json_to_stdout(args):
        emit_json(args, result.as_dict())
        return 0
    _print_result(result)
    if args.json is not None:
        emit_json(args, result.as_dict())
    return 0


def _print_result(result) -> None:
    e = result.error
    print(f"wrote {result.output} ({result.output_format}, {result.output_bytes:,} bytes): "
          f"{result.count:,} splats, SH degree {result.sh_degree_out} "
          f"(input: {result.source_format}, SH degree {result.sh_degree_in}) "
          f"in {result.seconds:.2f} s")
    for side, axes in (("input", result.input_axes), ("output", result.output_axes)):
        if axes is not None:
            print(f"SPZ axes of the {side}: {axes.describe()}")
    dropped = dropped_note(e["dropped"], result.output_format)
    if dropped:
        print(f"note: {dropped}")
    if e["bit_exact"]:
        print("round trip: bit-exact (every stored value identical)")
        return
    b = e.get("bounds") or {}
    print("round-trip error, max / mean" + (" (bound):" if b else ":"))
    print(_row("position", e["position"], "world units", b.get("position")))
    print(_row("scale", e["scale"], "(relative)", b.get("scale")))
    print(_row("opacity", e["opacity"], "", b.get("opacity")))
    print(_row("rotation", e["rotation"], "degrees", b.get("rotation")))
    print(_row("colour (DC)", e["color"], "(0-1 colour units; 1/255 = 0.00392)", b.get("color")))
    if e["color_outside_01"] and result.output_format == "splat":
        print(f"  ({e['color_outside_01']:,} input colour channels lie outside 0-1 and were "
              "clipped to 8 bits)")
    if result.sh_degree_in > 0:
        kept = "dropped" if result.sh_degree_out == 0 else f"degrees 1-{result.sh_degree_out}"
        print(_row("SH rest", e["sh_rest"], f"({kept})", b.get("sh_rest")) if e["sh_rest"] else
              f"  SH rest      {kept}")
