"""What each level of the frame-time budget costs in image quality (issue 27).

For each scene and three views of the interactive flight (start of the orbit, mid fly-in, the
rest view: :class:`splatgl.measure.bench.flight.Flight`) at 1280x720: the PSNR against the exact frame
of every render scale in ``SCALES`` times every splat budget (a level-of-detail cut, with the SH
degree capped at 0, as the budget's levels draw).  The quality model of
:func:`splatgl.interactive.budget.predicted_psnr` was fitted to this output
(docs/results/interactive-levels-psnr.json).  Without ``--repeats`` there is no timing, and it
may run beside other work::

    python benchmarks/interactive_levels.py SCENE... --out docs/results/interactive-levels-psnr.json

``--repeats N`` also times each level: the median of N draws at cameras a millisecond of flight
apart (each a moving frame: the order stage runs again), as the session draws it (order stage,
draw, upscale).  ``--times`` and ``--scales`` pick other views and scales, for example the
fill-bound donut views of docs/interactive.md::

    python benchmarks/interactive_levels.py donut_sh0.ply --repeats 4 --times 4.5,6.8,7.5 \
        --scales 0.5,0.4,0.35,0.3,0.25,0.2,0.15 --out donut-levels.json
"""

from __future__ import annotations

import argparse
import json
import math

import numpy as np
from _script import run

from splatgl.api import Renderer
from splatgl.measure.bench.flight import MOVE_END, Flight
from splatgl.measure.evaluation.metrics import psnr
from splatgl.formats import load_scene
from splatgl.interactive.budget import Level
from splatgl.interactive.draft import LevelRenderer
from splatgl.interactive.lod_cache import LodProvider
from splatgl.scene.settings import RenderSettings
from splatgl.writing.atomic import atomic_write_text

SCALES = (1.0, 0.7, 0.5, 0.35, 0.25)
BUDGETS = (None, 100_000, 50_000, 25_000, 12_000, 6_000)
TIMES = (0.0, 6.5, 8.0)


def _numbers(low: float, high: float, what: str):
    """An argparse type: comma-separated numbers in [low, high], or a one-line error naming them."""
    def parse(text: str) -> list[float]:
        try:
            values = [float(v) for v in text.split(",")]
        except ValueError:
            raise argparse.ArgumentTypeError(f"{what} must be comma-separated numbers, got {text!r}")
        bad = [v for v in values if not low <= v <= high]
        if bad:
            raise argparse.ArgumentTypeError(f"{what} must lie in [{low:g}, {high:g}], got {bad[0]:g}")
        return values
    return parse


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("scenes", nargs="+")
    p.add_argument("--out", required=True)
    p.add_argument("--repeats", type=int, default=0,
                   help="also time each level: the median of this many draws (default: no timing)")
    p.add_argument("--times", default=",".join(map(str, TIMES)),
                   type=_numbers(0.0, MOVE_END, "--times"),
                   help=f"seconds into the flight of the views (comma-separated, 0-{MOVE_END:g})")
    p.add_argument("--scales", default=",".join(map(str, SCALES)), type=_numbers(0.01, 1.0, "--scales"),
                   help="render scales (comma-separated, 0.01-1)")
    args = p.parse_args()
    if args.repeats < 0:
        p.error(f"--repeats must be 0 or more, got {args.repeats}")
    times, scales = args.times, args.scales
    renderer, rows = Renderer(), []
    for path in args.scenes:
        scene = load_scene(path)
        flight = Flight(scene, 1280, 720)
        lod = LodProvider(scene, scene.source.path, min_splats=1)
        lod.wait()
        levels = LevelRenderer(renderer, scene, RenderSettings(), lod)
        for t in times:
            cam = flight.camera(t)
            exact = levels.read(levels.draw(cam, Level()))
            for budget in BUDGETS:
                if budget is not None and budget >= scene.count:
                    continue
                for scale in scales:
                    sh = 0 if budget is not None and scene.sh_degree else None
                    level = Level(scale, budget, sh)
                    seconds = [levels.draw(flight.camera(t + 0.001 * k), level).seconds
                               for k in range(args.repeats)]
                    frame = levels.draw(cam, level)
                    value = psnr(levels.read(frame)[..., :3], exact[..., :3])
                    rows.append(dict(scene=path.split("/")[-1], t=t, count=scene.count, scale=scale,
                                     budget=budget, sh=sh, splats=frame.splats,
                                     psnr=None if math.isinf(value) else value,
                                     seconds=float(np.median(seconds)) if seconds else None))
                    print(rows[-1], flush=True)
        levels.release()
    atomic_write_text(args.out, json.dumps(rows))   # whole or not at all


if __name__ == "__main__":
    run(main)
