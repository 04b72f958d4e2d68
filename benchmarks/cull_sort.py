"""Cull against sort on the scale benchmark's scenes (issue 18, item 3): per camera model.

Runs only the quad path's order stage (``QuadRenderer.order``: cull, key construction,
sort; no draw) on an orbit of views, for a pinhole camera that frames the whole scene (almost
every splat visible), a pinhole camera at 0.2x that distance (most of the scene outside the
frustum), a 180-degree fisheye and an equirectangular panorama, and prints the median cull and
sort times and their ratio: for the NumPy cull and, where numba is installed (the ``fast``
extra), for the compiled one.  Run it under the timing gate on a shared machine::

    /work/tools/timed python benchmarks/cull_sort.py --sizes 0.1M,1M --frames 5

The scenes are the scale benchmark's (``splatgl.measure.bench.scale.scene_file``, built on first use).
"""

from __future__ import annotations

import argparse
import json
import statistics

import numpy as np

from splatgl.order import kernels as cull_kernel
from splatgl.measure.bench.scale import scene_file
from splatgl.measure.bench.machine import CPU_ONLY, describe, machine_info
from splatgl.measure.bench.scale import parse_sizes
from splatgl.cameras.poses import orbit
from splatgl.formats import load_scene
from splatgl.cameras.registry import retarget
from splatgl.cameras.view import View
from splatgl.renderers.quad import QuadRenderer
from splatgl.api import Renderer, default_camera
from splatgl.scene.settings import RenderSettings

VIEWS = ("pinhole", "pinhole-close", "fisheye", "equirect")


def cameras(scene, view: str, frames: int, width: int, height: int):
    """``frames + 1`` cameras of an orbit (2 degrees a step) for ``view``."""
    base = default_camera(scene, width, height)
    lo, hi = scene.robust_bounds
    centre = 0.5 * (lo + hi)
    dist = float(np.linalg.norm(base.center - centre)) * (0.2 if view == "pinhole-close" else 1.0)
    cams = [base.with_pose(orbit(centre, dist, 2.0 * i, 20.0)) for i in range(frames + 1)]
    if view == "fisheye":
        return [retarget(c, "fisheye", 180.0) for c in cams]
    if view == "equirect":
        return [retarget(c, "equirectangular") for c in cams]
    return cams


def _order_stage(quad, cams) -> tuple[float, float, int]:
    """Median cull and sort seconds over ``cams[1:]`` (the first view builds the cull data)."""
    cull, sort, kept = [], [], 0
    for i, cam in enumerate(cams):
        order = quad.order(View.of(cam, quad.options, quad.scene))
        if i:
            c, s = quad.rows.times.cull, quad.rows.times.sort
            cull.append(c)
            sort.append(s)
        kept = order.size
    return statistics.median(cull), statistics.median(sort), kept


def measure(n: int, frames: int, width: int, height: int) -> list[dict]:
    """Per view: the NumPy cull, and the compiled cull where numba is installed, each against
    its own run's sort."""
    renderer = Renderer()
    scene = load_scene(scene_file(n, 0), progress=lambda *a: None)
    quad = QuadRenderer(renderer.ctx, scene, RenderSettings(), renderer.programs)
    compiled = cull_kernel.kernel(wait=True) is not None  # loaded before anything is timed
    rows = []
    try:
        for view in VIEWS:
            cams = cameras(scene, view, frames, width, height)
            cull_kernel.set_policy("off")
            c, s, kept = _order_stage(quad, cams)
            row = {"splats": n, "view": view, "kept": int(kept), "cull_ms": 1e3 * c,
                   "sort_ms": 1e3 * s, "cull_over_sort": c / s, "compiled_cull_ms": None,
                   "compiled_sort_ms": None, "compiled_cull_over_sort": None}
            if compiled:
                cull_kernel.set_policy("wait")
                c, s, _ = _order_stage(quad, cams)
                row.update(compiled_cull_ms=1e3 * c, compiled_sort_ms=1e3 * s,
                           compiled_cull_over_sort=c / s)
            rows.append(row)
    finally:
        cull_kernel.set_policy("auto")
        quad.release()
        renderer.close()
    return rows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--sizes", default="0.1M,1M", help="scene sizes (splats), 'k'/'M' suffixes")
    p.add_argument("--frames", type=int, default=5, help="timed views per camera model")
    p.add_argument("--width", type=int, default=1280)
    p.add_argument("--height", type=int, default=720)
    p.add_argument("--json", help="also write the rows to this JSON file")
    args = p.parse_args()
    print(f"# {describe(machine_info(CPU_ONLY))}; medians of {args.frames} views; "
          f"{args.width}x{args.height}")
    print(f"# compiled cull (numba): {'yes' if cull_kernel.installed() else 'not installed'}")
    print(f"{'splats':>9} {'view':>14} {'kept':>9} {'cull ms':>8} {'sort ms':>8} {'cull/sort':>9}"
          f" {'compiled':>9} {'sort ms':>8} {'cull/sort':>9}")
    rows = []
    f = lambda v, spec: "-" if v is None else format(v, spec)
    for n in parse_sizes(args.sizes, (100_000, 1_000_000), "--sizes"):
        for r in measure(n, args.frames, args.width, args.height):
            rows.append(r)
            print(f"{r['splats']:>9,} {r['view']:>14} {r['kept']:>9,} {r['cull_ms']:>8.1f} "
                  f"{r['sort_ms']:>8.1f} {r['cull_over_sort']:>9.2f} "
                  f"{f(r['compiled_cull_ms'], '.1f'):>9} {f(r['compiled_sort_ms'], '.1f'):>8} "
                  f"{f(r['compiled_cull_over_sort'], '.2f'):>9}", flush=True)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=1)


if __name__ == "__main__":
    main()
