"""``splatgl edit IN... -o OUT``: crop, filter, remove floaters, decimate, drop SH bands, merge."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

from ..edit import edit_files
from ..edit.attributes import help_table
from ..edit.decimate import plural
from ..edit.options import inverted, operation
from ..errors import SplatglError
from ..scene.transform import parse_transform
from ._json_output import add_json_argument, check_json_target, emit_json, json_to_stdout
from ._memory import add_memory_argument, memory_budget
from ._outputs import add_force_argument, check_output
from ._spz_axes import add_spz_axes_argument

NAME = "edit"
ORDER = 26
HELP = ("crop, filter, remove floaters, decimate, drop SH bands and merge scenes "
        "(operations in the order given)")
DESCRIPTION = f"""Read one or more scenes, merge them into one (in input order, each placed by
its own --transform), apply the operations in the order they are given, and write OUT (format
from its extension, written atomically, never replacing a file without --force).  Each
operation's count of removed splats is printed; --dry-run prints them and writes nothing.

Operations (repeatable, in any order):
  --crop-box X0,Y0,Z0,X1,Y1,Z1   keep centres inside the box, faces included (inf and -inf
                                 allowed: a half-space or slab); or a JSON box
                                 '{{"min": [..], "max": [..], "rotate_deg": [rx, ry, rz],
                                 "translate": [..]}}' placed (rotated) by those keys
  --crop-sphere X,Y,Z,R          keep centres strictly inside the sphere
  --invert                       the --crop-box, --crop-sphere, --filter or --remove just
                                 before keeps the other splats (once: twice is refused)
  --filter EXPR                  keep the splats where EXPR holds
  --remove EXPR                  remove the splats where EXPR holds
  --remove-floaters [K=V,...]    remove isolated, faint splats: mean distance to the
                                 `neighbours` nearest centres above mean + `sigma` sd of all,
                                 and opacity below `opacity` (defaults neighbours=16, sigma=3,
                                 opacity=0.5); the threshold is printed
  --decimate N | P%              merge neighbour pairs by moment matching (the LOD merge) until
                                 N splats, or P percent, remain
  --sh-degree D                  keep SH bands up to degree D
  --drop-invalid                 drop rows with NaN/Inf or zero quaternions while reading
  --transform JSON               place each input (below); alone, it is the operation
Coordinates are the scene's own (the file's axes; after --transform when merging).  splat-
transform's -B/-S take PlayCanvas engine axes instead, x and y negated: its -B x0,y0,z0,x1,y1,z1
is --crop-box -x1,-y1,z0,-x0,-y0,z1 here (docs/editing.md).

EXPR compares attributes and numbers: <, <=, >, >=, ==, != (chains like 0.1 < opacity < 0.5),
+ - * /, abs() min() max() sqrt() log(), joined by and, or, not, with parentheses.  It is
parsed by a whitelist, never evaluated as Python.  Attributes (decoded values; index is the
splat's row in the input as splatgl pixel lists it, so --remove 'index == 123' deletes the
floater pixel names; refused after --decimate, which renumbers the rows):
{help_table()}

Merging: rows of every input one after another; the merged SH degree is the highest of the
inputs' (missing bands are zero: the colour is unchanged), or --sh-degree's.  --transform is
given once per input, in input order ('{{}}' for none): JSON or a JSON file with rotate_deg or
rotation, translate, scale, baked into positions, rotations, scales and the SH.

examples:
  splatgl edit scene.ply -o object.ply --crop-sphere 0,0,0,1.5 --remove 'opacity < 0.02'
  splatgl edit scene.ply -o clean.ply --remove-floaters --dry-run
  splatgl edit scene.ply -o small.sog --decimate 25% --sh-degree 1
  splatgl edit a.ply b.ply -o both.ply --transform '{{}}' --transform '{{"translate": [2, 0, 0]}}'
  splatgl edit scene.ply -o ring.ply --crop-sphere 0,0,0,1 --crop-sphere 0,0,0,0.5 --invert
  splatgl edit scene.ply -o clean.ply --remove 'index == 123'
  splatgl edit scene.ply -o moved.ply --transform '{{"rotate_deg": [180, 0, 0]}}'"""


class _Ordered(argparse.Action):
    """Records ``(option, value)`` in the order given (operations run in that order)."""

    def __call__(self, parser, namespace, values, option_string=None):
        ops = getattr(namespace, "operations", None) or []
        ops.append((self.dest.replace("_", "-"), values))
        namespace.operations = ops


#: Option values that are numbers (lists) starting with a minus sign: "-1,0,2.5,1e-3",
#: "-inf,-inf,0,inf,inf,1".  argparse takes only single negative numbers for values by default
#: and would read ``--crop-box -1,-1,-1,1,1,1`` as an unknown option.
_NUMBER = r"(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?|inf|infinity"
NEGATIVE_NUMBERS = re.compile(rf"^-({_NUMBER})(,\s*[-+]?({_NUMBER}))*$", re.IGNORECASE)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p._negative_number_matcher = NEGATIVE_NUMBERS  # the one argparse hook for it (see above)
    p.add_argument("inputs", nargs="+", type=Path, metavar="IN",
                   help="scene files (any supported format); several are merged in order")
    p.add_argument("-o", "--output", type=Path, default=None,
                   help="scene file to write; its extension picks the format")
    p.set_defaults(operations=None)
    for flag, metavar, text in (
            ("--crop-box", "BOX", "keep centres inside X0,Y0,Z0,X1,Y1,Z1 (or a JSON box)"),
            ("--crop-sphere", "X,Y,Z,R", "keep centres inside the sphere"),
            ("--filter", "EXPR", "keep the splats where EXPR holds"),
            ("--remove", "EXPR", "remove the splats where EXPR holds"),
            ("--decimate", "N|P%", "merge neighbours until N splats (or P%%) remain"),
            ("--sh-degree", "D", "keep SH bands up to degree D (0-3)")):
        p.add_argument(flag, action=_Ordered, metavar=metavar, help=text)
    p.add_argument("--remove-floaters", action=_Ordered, nargs="?", const="", metavar="K=V,...",
                   help="remove isolated, faint splats (neighbours=16,sigma=3,opacity=0.5)")
    p.add_argument("--invert", action=_Ordered, nargs=0,
                   help="the --crop-box, --crop-sphere, --filter or --remove just before keeps "
                        "the other splats")
    p.add_argument("--transform", action="append", default=None, metavar="JSON",
                   help="place an input (one per input, in order): rotate_deg or rotation, "
                        "translate, scale; alone, the edit is the transform")
    p.add_argument("--drop-invalid", action="store_true",
                   help="drop rows with NaN/Inf or zero quaternions while reading (counted)")
    p.add_argument("--allow-empty", action="store_true",
                   help="write a scene of zero splats instead of refusing it")
    p.add_argument("--dry-run", action="store_true",
                   help="print what each operation would remove; write nothing")
    add_force_argument(p)
    add_memory_argument(p, "binary PLY inputs whose scene exceeds it are edited a block of rows "
                           "at a time into a .ply, .splat or .compressed.ply (crops, filters, "
                           "--sh-degree, --transform, merges; --remove-floaters and --decimate "
                           "per spatial chunk; other outputs are refused)")
    add_spz_axes_argument(p)
    add_json_argument(p, "the report (inputs, one entry per operation, the result)")


def operations_from(pairs) -> list:
    """The operations of the recorded ``(option, value)`` pairs, --invert applied."""
    ops: list = []
    previous = None
    for name, value in pairs or []:
        if name == "invert":
            if not ops:
                raise SplatglError("--invert must follow a --crop-box, --crop-sphere, --filter "
                                   "or --remove")
            if previous == "invert":
                raise SplatglError(f"--invert given twice after --{ops[-1].name} (the second "
                                   "would undo the first): give it once")
            ops[-1] = inverted(ops[-1])
        else:
            ops.append(operation(name, value))
        previous = name
    return ops


def run(args: argparse.Namespace) -> int:
    check_json_target(args, {"OUT": args.output})  # nor IN or --transform; existing: --force
    if not args.dry_run:
        check_output(args, args.output, "-o")  # nor a --transform file it reads
    ops = operations_from(args.operations)
    transforms = None if args.transform is None else [parse_transform(t) for t in args.transform]
    moved = any(t is not None and not t.is_identity for t in transforms or [])
    if not ops and len(args.inputs) == 1 and not args.drop_invalid and not moved:
        raise SplatglError("edit: no operation given (see splatgl edit --help); to change the "
                           "format only, use splatgl convert")
    report = edit_files(args.inputs, args.output, ops, transforms, drop_invalid=args.drop_invalid,
                        allow_empty=args.allow_empty, force=args.force, dry_run=args.dry_run,
                        spz_axes=args.spz_axes, memory=memory_budget(args))
    if not json_to_stdout(args):
        _print(report)
    if args.json is not None:
        emit_json(args, report.as_dict(), indent=2)
    return 0


def _print(report) -> None:
    for path, n in zip(report.inputs, report.input_counts):
        print(f"read   {path}: {plural(n, 'splat')}")
    if len(report.inputs) > 1:
        print(f"merged {sum(report.input_counts):,} splats from {len(report.inputs)} inputs")
    for step in report.steps:
        print(f"  {step.line()}")
    for note in report.notes:
        print(f"  note: {note}")
    if report.dry_run:
        print(f"dry run: would write {plural(report.count, 'splat')}, SH degree "
              f"{report.sh_degree}" + (f" to {report.output}" if report.output else "")
              + "; nothing written")
    else:
        print(f"wrote  {report.output} ({report.output_bytes:,} bytes): "
              f"{plural(report.count, 'splat')}, SH degree {report.sh_degree} in "
              f"{report.seconds:.2f} s")
