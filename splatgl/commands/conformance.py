"""``splatgl conformance export|render|score``: the conformance kit (:mod:`splatgl.conformance`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import SplatglError
from ..model.settings import RendererKind
from ..progress import default_progress
from ._json_output import add_json_argument, check_json_target, emit_json, json_to_stdout

NAME = "conformance"
ORDER = 35
HELP = "export the conformance kit, or score another renderer's images of it"
DESCRIPTION = """A conformance kit for splat renderers.

  export DIR          write the cases (scenes as PLY, cameras of every model as JSON, the
                      reference images as float EXR and PNG, tolerances, index.json, and a
                      README stating the conventions: pixel centres, y direction, SH layout,
                      alpha clamp, early stop)
  render DIR -o OUT   render every case with splatgl's own --renderer (the images a
                      conforming renderer writes)
  score DIR --images THEIRS/
                      a pass/fail table per case with the PSNR, the share of pixels off by
                      more than 4/255, and for each failure the approximation that best
                      explains it (compare --explain's knobs) or the check it failed (size,
                      upside down, background)

examples:
  splatgl conformance export kit/
  splatgl conformance render kit/ -o quad/ --renderer quad
  splatgl conformance score kit/ --images quad/"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="action", required=True, metavar="export|render|score")
    e = sub.add_parser("export", help="write the kit into DIR")
    e.add_argument("dir", type=Path, metavar="DIR")
    e.add_argument("--force", action="store_true", help="replace DIR if it exists")
    e.add_argument("--no-real", action="store_true",
                   help="leave out the shared real scenes (donut, guitar, biker)")
    e.add_argument("--no-stress", action="store_true", help="leave out the stress cases")
    r = sub.add_parser("render", help="render the kit's cases with splatgl")
    r.add_argument("dir", type=Path, metavar="DIR")
    r.add_argument("-o", "--output", type=Path, required=True, metavar="OUT",
                   help="folder for NAME.exr (or --format png)")
    r.add_argument("--renderer", choices=[k.value for k in RendererKind], default="quad",
                   help="splatgl's renderer (default quad)")
    r.add_argument("--format", choices=("exr", "png"), default="exr", help="image format (default exr)")
    s = sub.add_parser("score", help="score THEIRS/NAME.png (.exr, .webp, .jpg, .tif) against the kit")
    s.add_argument("dir", type=Path, metavar="DIR")
    s.add_argument("--images", type=Path, required=True, metavar="THEIRS",
                   help="folder with one image per case, named after it")
    s.add_argument("--no-explain", action="store_true",
                   help="do not look for the knob that explains each failure (faster)")
    add_json_argument(s, "the scores (one object)")


def run(args: argparse.Namespace) -> int:
    if args.action == "export":
        from ..conformance.cases import all_cases
        from ..conformance.export import export_kit
        from ..formats import load_scene
        from ._common import demo_scene_path

        if args.dir.exists() and not args.force:
            raise SplatglError(f"{args.dir}: exists; pass --force to replace it")
        cases = all_cases(load_scene(demo_scene_path()), real=not args.no_real,
                          stress=not args.no_stress)
        index = export_kit(args.dir, cases, args.force, default_progress())
        print(f"wrote {args.dir}: {len(index['cases'])} cases (index.json, README.md, cases/)")
        return 0
    if args.action == "render":
        from ..conformance.score import render_kit

        skipped = render_kit(args.dir, args.output, args.renderer, "." + args.format, default_progress())
        for line in skipped:
            print(f"skipped {line}")
        print(f"wrote {args.output}")
        return 0
    from ..conformance.score import score_kit, table

    check_json_target(args, {"--images": args.images})
    scores = score_kit(args.dir, args.images, not args.no_explain, default_progress())
    report = {"kit": str(args.dir), "images": str(args.images),
              "passed": sum(s.status == "pass" for s in scores), "cases": [s.as_dict() for s in scores]}
    if json_to_stdout(args):
        emit_json(args, report)
        return 0
    print(table(scores))
    if args.json is not None:
        emit_json(args, report)
    return 0
