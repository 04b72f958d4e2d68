"""The CPU renderer against the quad path: exact frames along the interactive flight's orbit.

For each scene, at 1280x720 (``--width``/``--height``), ``--frames`` views of the flight's
orbit, each drawn by the quad path (cull, sort, upload, pre-pass, draw and readback: what
``splatgl render`` pays) and by the CPU renderer (``--renderer cpu``), the two alternating view
by view so that both see the same machine state.  Prints the medians, their ratio and the CPU
renderer's stages, and the PSNR of both against the float32 NumPy reference on one view.
``--json FILE`` writes the figures (atomically).

    python benchmarks/cpu_renderer.py SCENE [SCENE ...] [--frames 15] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import tempfile
import time

import numpy as np
from _script import run

ORBIT_STEP = 0.05       # seconds of the flight's orbit between timed views (1.8 degrees)


def _psnr(img: np.ndarray, ref: np.ndarray) -> float:
    mse = float(np.mean((img[..., :3] - ref[..., :3]) ** 2))
    return float("inf") if mse == 0 else 10.0 * np.log10(1.0 / mse)


def measure(path: str, width: int, height: int, frames: int) -> dict:
    import splatgl
    from splatgl.measure.bench.flight import Flight
    from splatgl.scene.settings import RendererKind
    from splatgl.reference import render_reference

    scene = splatgl.load_scene(path)
    settings = splatgl.default_settings(scene)
    flight = Flight(scene, width, height)
    cameras = [flight.camera(ORBIT_STEP * i) for i in range(frames + 1)]
    times = {"quad": [], "cpu": []}
    stages = []
    with splatgl.Renderer() as r:
        for kind in ("quad", "cpu"):                        # upload, compile: untimed
            r.render(scene, cameras[0], settings, kind)
        for cam in cameras[1:]:
            for kind in ("quad", "cpu"):
                t0 = time.perf_counter()
                r.render(scene, cam, settings, kind)
                times[kind].append(time.perf_counter() - t0)
            t = r.renderer_for(scene, settings, RendererKind.CPU).last_times
            stages.append((t.project, t.sort, t.bin, t.rasterize))
        ref = render_reference(scene, cameras[-1], settings, np.float32).rgba
        psnr = {kind: _psnr(r.render(scene, cameras[-1], settings, kind), ref)
                for kind in ("quad", "cpu")}
    med = {k: statistics.median(v) for k, v in times.items()}
    return {"scene": os.path.basename(path), "splats": scene.count, "frames": frames,
            "quad_ms": med["quad"] * 1e3, "cpu_ms": med["cpu"] * 1e3,
            "quad_over_cpu": med["quad"] / med["cpu"],
            "cpu_stages_ms": dict(zip(("project", "sort", "bin", "rasterize"),
                                      (statistics.median(s) * 1e3 for s in zip(*stages)))),
            "psnr_db": psnr}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("scenes", nargs="+")
    p.add_argument("--frames", type=int, default=15, help="timed views per scene (default 15)")
    p.add_argument("--width", type=int, default=1280)
    p.add_argument("--height", type=int, default=720)
    p.add_argument("--json", default=None, metavar="FILE", help="also write the figures here")
    args = p.parse_args()
    if args.frames < 1:
        p.error(f"--frames must be at least 1, got {args.frames}")
    if args.width < 1 or args.height < 1:
        p.error(f"--width and --height must be positive, got {args.width}x{args.height}")
    missing = [s for s in args.scenes if not os.path.isfile(s)]
    if missing:
        p.error(f"no such scene file: {missing[0]}")
    from splatgl.measure.bench.machine import describe, probe_machine
    machine = probe_machine()
    print(describe(machine), flush=True)
    results = {"machine": machine, "python": platform.python_version(), "scenes": []}
    for path in args.scenes:
        m = measure(path, args.width, args.height, args.frames)
        results["scenes"].append(m)
        st = m["cpu_stages_ms"]
        print(f"{m['scene']} ({m['splats']:,} splats), {args.width}x{args.height}, medians of "
              f"{args.frames} views: quad {m['quad_ms']:.0f} ms, cpu {m['cpu_ms']:.0f} ms, "
              f"quad/cpu {m['quad_over_cpu']:.2f}; cpu stages project {st['project']:.0f}, "
              f"sort {st['sort']:.0f}, bin {st['bin']:.0f}, rasterize {st['rasterize']:.0f} ms; "
              f"PSNR against the reference: quad {m['psnr_db']['quad']:.1f} dB, "
              f"cpu {m['psnr_db']['cpu']:.1f} dB", flush=True)
    if args.json:
        folder = os.path.dirname(os.path.abspath(args.json))
        fd, tmp = tempfile.mkstemp(dir=folder, suffix=".tmp")
        with os.fdopen(fd, "w") as f:
            json.dump(results, f, indent=1)
        os.replace(tmp, args.json)


if __name__ == "__main__":
    run(main)
