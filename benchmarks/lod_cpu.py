"""The CPU stages of a level-of-detail view, NumPy against compiled (issue 18).

For each frame of the LOD benchmark's fly-through (6x to 0.5x the framing distance) on the scale
benchmark's scenes: the cut's selection (``select_cut_weights`` at T=1px, band 2, with the
renderer's switch to the leaves), the cull of the cut's rows (``rows_keys``: NumPy over the
gathered rows, compiled in place) and the sort of its keys, each the median of ``--repeats``
runs, and whether both paths gave the same cut and keys.  Needs numba (the ``fast`` extra) for
the compiled columns.  Run it alone on the machine (it times)::

    python benchmarks/lod_cpu.py --sizes 3M,6M --json-lines docs/results/lod-cpu.jsonl
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from splatgl.order import kernels as cull_kernel
from splatgl.measure.bench.lod_bench import cameras, lod_file
from splatgl.measure.bench.scale import scene_file
from splatgl.measure.bench.machine import CPU_ONLY, describe, machine_info
from splatgl.measure.bench.runner import median_seconds
from splatgl.measure.bench.scale import parse_sizes
from splatgl.order.cull import CullData
from splatgl.order.chunks import keys_order, rows_keys
from splatgl.lod.cut import CutData, select_cut_weights
from splatgl.lod.io import read_lod
from splatgl.lod.selection import SKIP_NODES_PER_LEAF
from splatgl.cameras.view import anchored_camera
from splatgl.scene.settings import RenderSettings, resolve_near


def _median_ms(fn, repeats: int):
    """(median milliseconds, last result) of ``repeats`` calls of ``fn``."""
    seconds, result = median_seconds(fn, repeats)
    return 1e3 * seconds, result


def measure(n: int, repeats: int, kern) -> list[dict]:
    tree = read_lod(lod_file(scene_file(n, 0)))
    scene = tree.nodes
    data, cull_data = CutData.from_tree(tree), CullData.from_scene(scene)
    near = resolve_near(RenderSettings(), scene.robust_radius)
    rows = []
    for distance, cam in cameras(scene, 1280, 720, 5)["fly"]:
        anchored = anchored_camera(cam, scene.anchor)
        select = lambda k: select_cut_weights(data, cam, 1.0, 2.0, SKIP_NODES_PER_LEAF, kern=k)
        s_np, want = _median_ms(lambda: select(None), repeats)
        s_c, got = _median_ms(lambda: select(kern), repeats)
        row = {"splats": n, "distance": distance, "nodes": None, "select_numpy_ms": s_np,
               "select_compiled_ms": s_c,
               "same_cut": all((a is None and b is None) or np.array_equal(a, b)
                               for a, b in zip(want, got))}
        ids = want[0]
        if ids is not None:  # a cut (else the view draws the leaves: nothing more to time)
            cull = lambda k: rows_keys(cull_data, ids, anchored, near, False, 1.0, k)
            c_np, keys_np = _median_ms(lambda: cull(None), repeats)
            c_c, keys = _median_ms(lambda: cull(kern), repeats)
            sort_ms, _ = _median_ms(lambda: keys_order(keys), repeats)
            row.update(nodes=int(ids.size), cull_numpy_ms=c_np, cull_compiled_ms=c_c,
                       sort_ms=sort_ms,
                       same_keys=bool(np.array_equal(np.sort(keys_np), np.sort(keys))))
        rows.append(row)
    return rows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--sizes", default="3M", help="scene sizes (splats), 'k'/'M' suffixes")
    p.add_argument("--repeats", type=int, default=3, help="runs per stage (median)")
    p.add_argument("--json-lines", help="also write one JSON row per frame to this file")
    args = p.parse_args()
    kern = cull_kernel.kernel(wait=True)
    if kern is None:
        raise SystemExit("lod_cpu.py: needs numba (pip install '.[fast]')")
    print(f"# {describe(machine_info(CPU_ONLY))}; medians of {args.repeats}; T=1px, band 2; ms")
    print(f"{'splats':>9} {'dist':>5} {'nodes':>9} {'select np':>9} {'compiled':>8} "
          f"{'cull np':>8} {'compiled':>8} {'sort':>6} same")
    out = open(args.json_lines, "w") if args.json_lines else None
    try:
        for n in parse_sizes(args.sizes, (3_000_000,), "--sizes"):
            for r in measure(n, args.repeats, kern):
                f = lambda key: "-" if key not in r else f"{r[key]:.0f}"
                print(f"{n:>9,} {r['distance']:>5.2f} {r['nodes'] or 'leaves':>9} "
                      f"{r['select_numpy_ms']:>9.0f} {r['select_compiled_ms']:>8.0f} "
                      f"{f('cull_numpy_ms'):>8} {f('cull_compiled_ms'):>8} {f('sort_ms'):>6} "
                      f"{r['same_cut'] and r.get('same_keys', True)}", flush=True)
                if out:
                    out.write(json.dumps(r) + "\n")
    finally:
        if out:
            out.close()


if __name__ == "__main__":
    main()
