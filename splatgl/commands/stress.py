"""``splatgl stress``: run the numerical stress cases and print the report."""

from __future__ import annotations

import argparse
import sys

from ..errors import SplatglError
from ..measure.stress import CASES, case_by_name
from ..measure.stress.run import RENDERERS, default_renderers, format_report, results_json, run_cases
from ._json_output import add_json_argument, check_json_target, emit_json, json_to_stdout
from ._outputs import add_force_argument

NAME = "stress"
ORDER = 80
HELP = "run scenes built to break renderers and report NaN/Inf, error and time"
DESCRIPTION = """Render each stress case (extreme scales and anisotropy, degenerate quaternions,
splats at and behind the near plane, scenes far from the origin, extreme fields of view and
zooms, extreme opacities, 10,000 coincident splats, 1 x 1 and 8192 x 8192 images, edge-on
surfels) with the quad path, the tile renderer, the CPU renderer (where the fast extra is
installed) and the float32 NumPy reference, and compare each with the float64 reference.

The table gives, per case and renderer: whether every output value is finite, the max
absolute RGBA error, the case's bound, pass/fail and seconds.  The "fixes" section lists the
guards added to the renderers and what failed before each.  Exit status 1 when a row fails
(known, documented failures are shown as KNOWN and do not change it).

examples:
  splatgl stress
  splatgl stress --case far_1e7 --case near_plane
  splatgl stress --json --skip-slow
  splatgl stress --skip-slow --json stress.json"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--case", action="append", default=None, metavar="NAME",
                   help="run only this case (repeatable); names: "
                        + ", ".join(c.name for c in CASES))
    p.add_argument("--renderer", action="append", choices=RENDERERS, default=None,
                   help="run only this renderer (repeatable; default all, cpu where numba is "
                        "installed)")
    p.add_argument("--skip-slow", action="store_true",
                   help="leave out the slow cases (the 8192 x 8192 image, ~40 s and ~10 GB)")
    add_json_argument(p, "the report")
    add_force_argument(p)


def run(args: argparse.Namespace) -> int:
    try:
        cases = [case_by_name(n) for n in args.case] if args.case else list(CASES)
    except KeyError as exc:
        raise SplatglError(exc.args[0]) from None
    check_json_target(args)
    if args.skip_slow:
        cases = [c for c in cases if not c.slow]
    renderers = tuple(args.renderer) if args.renderer else default_renderers()
    if "cpu" in renderers:
        from ..renderers.registry import check
        check("cpu")

    def progress(case) -> None:
        if not json_to_stdout(args):
            print(f"running {case.name} ...", file=sys.stderr, flush=True)

    results = run_cases(cases, renderers, progress)
    if not json_to_stdout(args):
        print(format_report(results))
    if args.json is not None:
        emit_json(args, results_json(results), indent=2)
    failed = any(r.status in ("fail", "error") for res in results for r in res.rows)
    return 1 if failed else 0
