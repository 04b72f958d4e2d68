"""Cheaper splats at full quality (issue 27, item 6): the quad path's draw with one triangle per
splat instead of a four-vertex strip, against the quad, on the same views.

For each scene and view (the interactive flight's start, mid fly-in and rest views at
1280x720), the draw stage alone (upload and draw to a finish; the cull and sort are the same
for both) is timed ``--repeats`` times per variant, alternating variants, and the images are
compared (PSNR of the triangle's against the quad's; the image must not change).  Run it alone
on the machine (it times)::

    python benchmarks/cheaper_splats.py SCENE... --repeats 9 --json docs/results/cheaper-splats.json

``--drafts`` times the viewer's draft levels instead (``LevelRenderer.draw``: order stage, draw
and upscale, to a finish), with and without one triangle per splat, on the same views: the
drafts' PSNR against the exact frame shows what the triangle costs in quality there.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

import numpy as np

from splatgl.api import Renderer
from splatgl.measure.bench.flight import Flight
from splatgl.measure.bench.machine import describe, probe_machine
from splatgl.cameras.view import View
from splatgl.measure.evaluation.metrics import psnr
from splatgl.formats import load_scene
from splatgl.scene.settings import RenderSettings
from splatgl.interactive.budget import Level
from splatgl.interactive.draft import LevelRenderer
from splatgl.interactive.lod_cache import LodProvider
from splatgl.renderers.quad import composite

VARIANTS = ("quad", "triangle")


def set_variant(quad, name: str) -> None:
    """Switch ``quad`` (early termination off) to drawing ``name`` (one of VARIANTS)."""
    quad.use_triangles(name == "triangle")


def time_draw(quad, view: View, repeats: int) -> tuple[list[float], np.ndarray]:
    quad.order(view)
    target = quad.target(view)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        quad.draw(view, target)
        times.append(time.perf_counter() - t0)
    return times, target.read()


#: The draft levels timed by --drafts (the flight's usual picks on these scenes).
DRAFT_LEVELS = (Level(0.5, None, 0), Level(0.35, None, 0), Level(0.7, 50_000, 0),
                Level(0.5, 100_000, 0))


def time_drafts(renderer, path: str, repeats: int) -> list[dict]:
    """Rows of --drafts for the scene at ``path`` (module doc)."""
    scene = load_scene(path)
    settings = RenderSettings()
    lod = LodProvider(scene, Path(path))
    lod.wait()
    drafts = {name: LevelRenderer(renderer, scene, settings, lod, name == "triangle")
              for name in VARIANTS}
    flight = Flight(scene, 1280, 720)
    rows = []
    for t in (0.0, 6.5, 8.0):
        camera = flight.camera(t)
        exact = renderer.render(scene, camera, settings)
        for level in DRAFT_LEVELS:
            if level.budget is not None and (not lod.ready or level.budget >= scene.count):
                continue
            times = {name: [] for name in VARIANTS}
            images = {}
            for _ in range(repeats):
                for name in VARIANTS:
                    frame = drafts[name].draw(camera, level)
                    times[name].append(frame.seconds)
                    images[name] = drafts[name].read(frame)
            base = statistics.median(times["quad"])
            tri = statistics.median(times["triangle"])
            row = dict(scene=path.split("/")[-1], t=t, level=level.describe(),
                       quad_ms=base * 1e3, triangle_ms=tri * 1e3, triangle_ratio=tri / base,
                       quad_psnr=psnr(images["quad"][..., :3], exact[..., :3]),
                       triangle_psnr=psnr(images["triangle"][..., :3], exact[..., :3]))
            rows.append(row)
            print(row, flush=True)
    for d in drafts.values():
        d.release()
    return rows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("scenes", nargs="+")
    p.add_argument("--repeats", type=int, default=7)
    p.add_argument("--json", default=None)
    p.add_argument("--drafts", action="store_true", help="time the viewer's draft levels")
    args = p.parse_args()
    machine = probe_machine()
    print(describe(machine), flush=True)
    rows = []
    with Renderer() as renderer:
        for path in args.scenes:
            if args.drafts:
                rows += time_drafts(renderer, path, args.repeats)
                continue
            scene = load_scene(path)
            settings = RenderSettings(early_stop=False)
            quad = renderer.renderer_for(scene, settings)
            flight = Flight(scene, 1280, 720)
            for t in (0.0, 6.5, 8.0):
                view = View.of(flight.camera(t), settings, scene)
                results = {name: [] for name in VARIANTS}
                images = {}
                for _ in range(args.repeats):
                    for name in VARIANTS:
                        set_variant(quad, name)
                        times, img = time_draw(quad, view, 1)
                        results[name] += times
                        images[name] = composite(img, settings.background)
                set_variant(quad, "quad")
                base = statistics.median(results["quad"])
                row = dict(scene=path.split("/")[-1], t=t, splats=scene.count,
                           quad_ms=base * 1e3)
                for name in VARIANTS[1:]:
                    med = statistics.median(results[name])
                    row[f"{name}_ms"] = med * 1e3
                    row[f"{name}_ratio"] = med / base
                    value = psnr(images[name][..., :3], images["quad"][..., :3])
                    row[f"{name}_psnr"] = None if value == float("inf") else value
                rows.append(row)
                print(row, flush=True)
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"machine": machine, "rows": rows}, f, indent=1)


if __name__ == "__main__":
    main()
