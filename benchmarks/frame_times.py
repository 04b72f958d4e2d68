"""Frame time of the quad path split into cull, sort, upload, draw and readback.

    python benchmarks/frame_times.py [--width 1280 --height 720 --frames 7] [SCENE ...]

Without scenes it measures ../shared/scenes/ply/donut_sh0.ply (if present) and a synthetic
150k-splat SH3 scene.  Each frame moves the camera a little (an orbit step), so cull and sort
run every frame as they do in motion; the first (warm-up, shader compile) frame is dropped.
Prints per-stage medians in milliseconds.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from splatgl.cameras.view import View
from splatgl import RenderSettings, Renderer, default_camera, load_scene
from splatgl.cameras.poses import orbit
from splatgl.measure.bench.synthetic import synthetic_scene
from splatgl.scene.splats import Scene

REPO = Path(__file__).resolve().parent.parent


def measure(name: str, scene: Scene, width: int, height: int, frames: int) -> dict[str, float]:
    base = default_camera(scene, width, height)
    lo, hi = scene.robust_bounds
    centre = 0.5 * (lo + hi)
    distance = float(np.linalg.norm(base.center - centre))
    rows = []
    with Renderer() as renderer:
        quad = renderer.renderer_for(scene, RenderSettings())
        for i in range(frames + 1):
            cam = base.with_pose(orbit(centre, distance, 180.0 + 3.0 * i, 20.0))
            t0 = time.perf_counter()
            quad.render(View.of(cam, quad.options, scene))
            wall = time.perf_counter() - t0
            if i > 0:
                t = quad.last_times
                rows.append({"cull": t.cull, "sort": t.sort, "upload": t.upload, "prepass": t.prepass, "draw": t.draw,
                             "readback": t.readback, "total": wall})
    med = {k: statistics.median(r[k] for r in rows) * 1e3 for k in rows[0]}
    parts = "  ".join(f"{k} {v:7.1f}" for k, v in med.items())
    print(f"{name:<28} {scene.count:>8}  {parts}  (ms, median of {frames})")
    return med


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scenes", nargs="*", type=Path)
    ap.add_argument("--width", type=int, default=1280)
    ap.add_argument("--height", type=int, default=720)
    ap.add_argument("--frames", type=int, default=7)
    args = ap.parse_args(argv)
    jobs = [(p.name, load_scene(p)) for p in args.scenes]
    if not jobs:
        donut = REPO.parent / "shared" / "scenes" / "ply" / "donut_sh0.ply"
        if donut.is_file():
            jobs.append((donut.name, load_scene(donut)))
        jobs.append(("synthetic 150k SH3", synthetic_scene(150_000)))
    print(f"quad path, {args.width}x{args.height}, RGBA32F, ellipse extent")
    for name, scene in jobs:
        measure(name, scene, args.width, args.height, args.frames)
    return 0


if __name__ == "__main__":
    sys.exit(main())
