"""``splatgl conformance export|render|score``: the conformance kit (:mod:`splatgl.measure.conformance`)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..renderers.registry import names as renderer_names
from ..scene.settings import RendererKind
from ..progress import default_progress
from ._common import add_force_argument
from ._json_output import add_json_argument, check_json_target, emit_json, json_to_stdout

NAME = "conformance"
ORDER = 35
HELP = "export the conformance kit, or score another renderer's images of it"
DESCRIPTION = """A conformance kit for splat renderers.

  export DIR          write the cases (scenes as PLY, cameras of every model as JSON, the
                      reference images as float EXR and PNG, tolerances, index.json, and a
                      README stating the conventions: pixel centres, y direction, SH layout,
                      alpha clamp, early stop); --force replaces an older kit, never a
                      folder holding anything else
  render DIR -o OUT   render every case with splatgl's own --renderer (the images a
                      conforming renderer writes)
  score DIR --images THEIRS/
                      a pass/fail table per case with the PSNR, the share of pixels off by
                      more than 4/255, and for each failure the approximation that best
                      explains it (compare --explain's knobs) or the check it failed (size,
                      upside down, background, colours below 0); exits 1 when a case
                      fails or its image is missing (0 when every case passes), so CI can
                      gate on it

examples:
  splatgl conformance export kit/
  splatgl conformance render kit/ -o quad/ --renderer quad
  splatgl conformance score kit/ --images quad/"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="action", required=True, metavar="export|render|score")
    e = sub.add_parser("export", help="write the kit into DIR")
    e.add_argument("dir", type=Path, metavar="DIR")
    add_force_argument(e, "replace DIR where it is an older kit (or a file); a folder holding "
                          "anything else is refused")
    e.add_argument("--no-real", action="store_true",
                   help="leave out the shared real scenes (donut, guitar, biker)")
    e.add_argument("--no-stress", action="store_true", help="leave out the stress cases")
    r = sub.add_parser("render", help="render the kit's cases with splatgl")
    r.add_argument("dir", type=Path, metavar="DIR")
    r.add_argument("-o", "--output", type=Path, required=True, metavar="OUT",
                   help="folder for NAME.exr (or --format png)")
    r.add_argument("--renderer", choices=renderer_names(), default="quad",
                   help="splatgl's renderer (default quad)")
    r.add_argument("--format", choices=("exr", "png"), default="exr", help="image format (default exr)")
    add_force_argument(r, "replace images in OUT that exist (never the kit's own files)")
    s = sub.add_parser("score", help="score THEIRS/NAME.png (.exr, .webp, .jpg, .tif) against the kit")
    s.add_argument("dir", type=Path, metavar="DIR")
    s.add_argument("--images", type=Path, required=True, metavar="THEIRS",
                   help="folder with one image per case, named after it")
    s.add_argument("--no-explain", action="store_true",
                   help="do not look for the knob that explains each failure (faster)")
    add_json_argument(s, "the scores (one object)")
    add_force_argument(s)


def _export(args: argparse.Namespace) -> int:
    from ..measure.bench.real_scenes import shared_scenes_dir
    from ..measure.conformance.cases import all_cases, missing_real
    from ..measure.conformance.export import export_kit
    from ..measure.conformance.kit_folder import check_export_target
    from ..formats import load_scene
    from ._common import demo_scene_path

    check_export_target(args.dir, args.force)
    missing = [] if args.no_real else missing_real()
    if missing:
        print(f"note: {len(missing)} real-scene case{'s' if len(missing) > 1 else ''} left out: "
              f"{', '.join(missing)} not found in {shared_scenes_dir()} (set "
              "$SPLATGL_SHARED_SCENES, or pass --no-real)", file=sys.stderr)
    cases = all_cases(load_scene(demo_scene_path()), real=not args.no_real,
                      stress=not args.no_stress)
    index = export_kit(args.dir, cases, args.force, default_progress())
    print(f"wrote {args.dir}: {len(index['cases'])} cases (index.json, README.md, cases/)")
    return 0


def _render(args: argparse.Namespace) -> int:
    from ..measure.conformance.score import check_render_output, load_index, render_kit

    suffix = "." + args.format
    check_render_output(args.dir, args.output, load_index(args.dir), suffix, args.force)
    skipped = render_kit(args.dir, args.output, args.renderer, suffix, default_progress(), args.force)
    for line in skipped:
        print(f"skipped {line}")
    print(f"wrote {args.output}")
    return 0


def _score(args: argparse.Namespace) -> int:
    from ..measure.conformance.index import kit_files
    from ..measure.conformance.score import load_index, score_kit, table
    from ..writing.outputs import check_not_an_input

    index = load_index(args.dir)
    check_json_target(args, {"--images": args.images})
    if args.json is not None and not json_to_stdout(args):
        check_not_an_input(args.json, "--json", {"the kit's file": kit_files(args.dir, index)})
    scores = score_kit(args.dir, args.images, not args.no_explain, default_progress())
    passed = sum(s.status == "pass" for s in scores)
    report = {"kit": str(args.dir), "images": str(args.images), "passed": passed,
              "cases": [s.as_dict() for s in scores]}
    code = 0 if passed == len(scores) else 1
    if json_to_stdout(args):
        emit_json(args, report)
        return code
    print(table(scores))
    if args.json is not None:
        emit_json(args, report)
    return code


def run(args: argparse.Namespace) -> int:
    return {"export": _export, "render": _render, "score": _score}[args.action](args)
