"""Cheaper splats at full quality (issue 27, item 6): the quad path's draw with one triangle per
splat instead of a four-vertex strip, against the quad, on the same views.

For each scene and view (the interactive flight's start, mid fly-in and rest views at
1280x720), the draw stage alone (upload and draw to a finish; the cull and sort are the same
for both) is timed ``--repeats`` times per variant, alternating variants, and the images are
compared (PSNR of the triangle's against the quad's; the image must not change).  Run it alone
on the machine (it times)::

    python benchmarks/cheaper_splats.py SCENE... --repeats 9 --json docs/results/cheaper-splats.json
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

import moderngl
import numpy as np

from splatgl.api import Renderer
from splatgl.bench.flight import Flight
from splatgl.bench.machine import describe, probe_machine
from splatgl.cameras.view import View
from splatgl.evaluation.metrics import psnr
from splatgl.formats import load_scene
from splatgl.model.settings import RenderSettings
from splatgl.renderers import quad_gpu
from splatgl.renderers.quad import composite

VARIANTS = ("quad", "triangle")


_plain_draw = quad_gpu.QuadResources.draw_range


def _triangle_draw(self, prog, start: int, n: int) -> None:
    """QuadResources.draw_range with one triangle (3 vertices) per instance."""
    self.ctx.enable(moderngl.BLEND)
    prog["u_base"].value = start
    self.vertex_array(prog, None).render(moderngl.TRIANGLES, vertices=3, instances=n)


def set_variant(quad, name: str) -> None:
    """Switch ``quad`` (a QuadRenderer on the compute pre-pass, early termination off) to
    drawing ``name`` (one of VARIANTS): the TRIANGLE_PER_SPLAT define and 3-vertex draws."""
    quad.frame_extra.pop("TRIANGLE_PER_SPLAT", None)
    quad_gpu.QuadResources.draw_range = _plain_draw
    if name == "triangle":
        quad.frame_extra["TRIANGLE_PER_SPLAT"] = 1
        quad_gpu.QuadResources.draw_range = _triangle_draw


def time_draw(quad, view: View, repeats: int) -> tuple[list[float], np.ndarray]:
    quad.order(view)
    target = quad.target(view)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        quad.draw(view, target)
        times.append(time.perf_counter() - t0)
    return times, target.read()


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("scenes", nargs="+")
    p.add_argument("--repeats", type=int, default=7)
    p.add_argument("--json", default=None)
    args = p.parse_args()
    machine = probe_machine()
    print(describe(machine), flush=True)
    rows = []
    with Renderer() as renderer:
        for path in args.scenes:
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
