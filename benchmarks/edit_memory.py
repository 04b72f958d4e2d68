"""Peak memory of ``splatgl edit`` on the scale benchmark's scenes (issue 30: streaming-safe,
bounded extra memory).

    python benchmarks/edit_memory.py [--size 6M] [--out docs/results/edit-memory-6M.json]

For one scene of the scale benchmark (:func:`splatgl.measure.bench.scale.scene_file`, built and cached
on first use), each case runs in a fresh child process (so its peak resident memory, VmHWM, is
its own): ``load`` only reads the scene; every other case runs ``splatgl edit`` with one
operation and writes a PLY (atomically, into a temporary folder).  "extra" is the case's peak
minus the load's peak: what the operation and the write add on top of holding the scene.  The
merge case reads the half-size scene twice.  Seconds are printed too but are not benchmark
figures (other work may share the machine).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from splatgl.measure.bench.scale import parse_sizes, scene_file  # noqa: E402

#: (case, edit options); {box} and {sphere} are filled from the scene's robust bounds so that
#: the crops keep about half of it.
CASES = (
    ("crop-box", ["--crop-box", "{box}"]),
    ("crop-sphere", ["--crop-sphere", "{sphere}"]),
    ("filter", ["--remove", "opacity < 0.1 or anisotropy > 50"]),
    ("sh-degree", ["--sh-degree", "0"]),
    ("remove-floaters", ["--remove-floaters"]),
    ("decimate", ["--decimate", "50%"]),
)

CHILD = """
import json, sys, time
from splatgl.cli import build_parser, main
t = time.perf_counter()
argv = json.loads(sys.argv[1])
if argv[0] == "load":  # the same imports as an edit, then the scene
    build_parser()
    from splatgl.formats import load_scene
    n = load_scene(argv[1]).count
    code = 0
else:
    code = main(argv)
for line in open("/proc/self/status"):
    if line.startswith("VmHWM:"):
        peak = int(line.split()[1]) / 1e3
print(json.dumps({"code": code, "peak_mb": peak, "seconds": time.perf_counter() - t}),
      file=sys.stderr)
"""


def run_child(argv: list[str]) -> dict:
    env = {**os.environ, "PYTHONPATH": str(REPO), "SPLATGL_PROGRESS": "0"}
    proc = subprocess.run([sys.executable, "-c", CHILD, json.dumps(argv)], capture_output=True,
                          text=True, cwd=REPO, env=env)
    last = proc.stderr.strip().splitlines()[-1]
    out = json.loads(last)
    out["stdout"] = proc.stdout.strip().splitlines()[-3:]
    return out


def _crops(path: Path) -> dict:
    """A box (the lower half along x of the robust bounds) and a sphere (around their centre)."""
    from splatgl.formats import load_scene

    lo, hi = load_scene(path).robust_bounds
    mid = (lo + hi) / 2
    box = [*lo, mid[0], *hi[1:]]
    radius = 0.2 * float(((hi - lo) ** 2).sum() ** 0.5)
    return {"box": ",".join(f"{v:.6g}" for v in box),
            "sphere": ",".join(f"{v:.6g}" for v in [*mid, radius])}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--size", default="6M", help="scene size (e.g. 6M, 300k)")
    p.add_argument("--out", type=Path, default=None, help="write the rows as JSON here")
    args = p.parse_args(argv)
    n = parse_sizes(args.size, (), "--size")[0]
    scene = scene_file(n, 0)
    half = scene_file(n // 2, 0)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        load = run_child(["load", str(scene)])
        print(f"scene {scene.name}: {scene.stat().st_size / 1e6:.0f} MB file; load peak "
              f"{load['peak_mb']:.0f} MB ({load['seconds']:.1f} s)", flush=True)
        rows.append({"case": "load", **load})
        fill = _crops(scene)
        cases = [(name, [str(scene), "-o", f"{tmp}/{name}.ply", *(o.format(**fill) for o in opts)])
                 for name, opts in CASES]
        cases.append(("merge 2 x half", [str(half), str(half), "-o", f"{tmp}/merge.ply"]))
        for name, edit in cases:
            t = time.perf_counter()
            row = run_child(["edit", *edit])
            row.update(case=name, extra_mb=row["peak_mb"] - load["peak_mb"])
            rows.append(row)
            print(f"{name:<16} peak {row['peak_mb']:7.0f} MB  extra {row['extra_mb']:+7.0f} MB  "
                  f"({time.perf_counter() - t:.0f} s) {row['stdout'][-1] if row['stdout'] else ''}",
                  flush=True)
    if args.out:
        args.out.write_text(json.dumps({"scene": scene.name, "splats": n, "rows": rows},
                                       indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
