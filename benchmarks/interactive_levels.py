"""What each level of the frame-time budget costs in image quality (issue 27).

For each scene and three views of the interactive flight (start of the orbit, mid fly-in, the
rest view: :class:`splatgl.bench.flight.Flight`) at 1280x720: the PSNR against the exact frame
of every render scale in ``SCALES`` times every splat budget (a level-of-detail cut, with the SH
degree capped at 0, as the budget's levels draw).  The quality model of
:func:`splatgl.interactive.budget.predicted_psnr` was fitted to this output
(docs/results/interactive-levels-psnr.json).  No timing: it may run beside other work::

    python benchmarks/interactive_levels.py SCENE... --out docs/results/interactive-levels-psnr.json
"""

from __future__ import annotations

import argparse
import json
import math

from splatgl.api import Renderer
from splatgl.bench.flight import Flight
from splatgl.evaluation.metrics import psnr
from splatgl.formats import load_scene
from splatgl.interactive.budget import Level
from splatgl.interactive.draft import LevelRenderer
from splatgl.interactive.lod_cache import LodProvider
from splatgl.model.settings import RenderSettings

SCALES = (1.0, 0.7, 0.5, 0.35, 0.25)
BUDGETS = (None, 100_000, 50_000, 25_000, 12_000, 6_000)
TIMES = (0.0, 6.5, 8.0)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("scenes", nargs="+")
    p.add_argument("--out", required=True)
    args = p.parse_args()
    renderer, rows = Renderer(), []
    for path in args.scenes:
        scene = load_scene(path)
        flight = Flight(scene, 1280, 720)
        lod = LodProvider(scene, scene.source.path, min_splats=1)
        lod.wait()
        levels = LevelRenderer(renderer, scene, RenderSettings(), lod)
        for t in TIMES:
            cam = flight.camera(t)
            exact = levels.read(levels.draw(cam, Level()))
            for budget in BUDGETS:
                if budget is not None and budget >= scene.count:
                    continue
                for scale in SCALES:
                    sh = 0 if budget is not None and scene.sh_degree else None
                    frame = levels.draw(cam, Level(scale, budget, sh))
                    value = psnr(levels.read(frame)[..., :3], exact[..., :3])
                    rows.append(dict(scene=path.split("/")[-1], t=t, count=scene.count, scale=scale,
                                     budget=budget, sh=sh, splats=frame.splats,
                                     psnr=None if math.isinf(value) else value))
                    print(rows[-1], flush=True)
        levels.release()
    with open(args.out, "w") as f:
        json.dump(rows, f)


if __name__ == "__main__":
    main()
