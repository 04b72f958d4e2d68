"""A lower bound on an exact frame's time on llvmpipe: its CPU work spread perfectly over the cores.

For each scene, at 1280x720 along the start of the interactive flight's orbit (medians of
``--frames``), two renderers:

- ``quad``: the quad path's exact frame (cull, sort, upload, pre-pass and draw; no readback);
- ``limit``: the same quads with trivial shaders (``splatgl/measure/bench/limit.py``: the draw only),
  what llvmpipe costs for this geometry, blending and target at all.

Each runs twice, with llvmpipe's default threads and with ``LP_NUM_THREADS=0`` (everything in
the drawing thread: the frame's whole CPU work, one core).  Half the one-thread time is what the
frame could take at best on two cores.  With ``--peer MS`` (another renderer's frame time for
the same scene, e.g. limacv's from the peer race) it also prints the largest ratio peer/frame
that bound allows.

    python benchmarks/same_work_bound.py SCENE [SCENE ...] [--frames 9] [--peer MS ...]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys

import numpy as np
from _script import run

WIDTH, HEIGHT = 1280, 720
#: Seconds of the flight's orbit between timed frames (1.8 degrees).
ORBIT_STEP = 0.05


def _time(scene_path: str, kind: str, frames: int) -> float:
    """Median seconds of ``kind`` ("quad" or "limit") frames, in this process."""
    import splatgl
    from splatgl.measure.bench.flight import Flight
    from splatgl.measure.bench.limit import LimitRenderer
    from splatgl.cameras.view import View
    from splatgl.gl.context import create_headless_context
    from splatgl.renderers.quad import QuadRenderer

    scene = splatgl.load_scene(scene_path)
    settings = splatgl.default_settings(scene)
    flight = Flight(scene, WIDTH, HEIGHT)
    ctx = create_headless_context()
    renderer = (LimitRenderer if kind == "limit" else QuadRenderer)(ctx, scene, settings)

    def view(i: int) -> View:                   # the flight's orbit: every frame a new view
        return View.of(flight.camera(ORBIT_STEP * i), settings, scene)

    renderer.render(view(0))          # compile and upload, untimed
    seconds = []
    for i in range(frames):
        renderer.render(view(i))
        t = renderer.last_times
        seconds.append(t.draw if kind == "limit" else t.total - t.readback)
    return float(np.median(seconds))


def _child(scene: str, kind: str, frames: int, one_thread: bool) -> float:
    env = dict(os.environ)
    if one_thread:
        env["LP_NUM_THREADS"] = "0"
    else:
        env.pop("LP_NUM_THREADS", None)
    out = subprocess.run([sys.executable, __file__, scene, "--frames", str(frames), "--kind", kind],
                         env=env, capture_output=True, text=True)
    if out.returncode != 0:
        last = out.stderr.strip().splitlines()[-1] if out.stderr.strip() else f"exit {out.returncode}"
        raise SystemExit(f"same_work_bound.py: {kind} on {scene} failed: {last}")
    return float(out.stdout.strip().splitlines()[-1])


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("scenes", nargs="+")
    p.add_argument("--frames", type=int, default=9, help="timed frames per run (default 9)")
    p.add_argument("--peer", type=float, nargs="*", default=[], metavar="MS",
                   help="another renderer's frame time per scene (ms), for the ratio bound")
    p.add_argument("--kind", choices=("quad", "limit"), help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.frames < 1:
        p.error(f"--frames must be at least 1, got {args.frames}")
    missing = [s for s in args.scenes if not os.path.isfile(s)]
    if missing:
        p.error(f"no such scene file: {missing[0]}")
    if args.kind is not None:                     # a child: one renderer, print its median
        print(_time(args.scenes[0], args.kind, args.frames), flush=True)
        return
    if args.peer and len(args.peer) != len(args.scenes):
        p.error(f"--peer needs one time per scene ({len(args.scenes)}), got {len(args.peer)}")
    for n, scene in enumerate(args.scenes):
        print(f"{os.path.basename(scene)} at {WIDTH}x{HEIGHT}, medians of {args.frames} frames:")
        for kind in ("quad", "limit"):
            threads = _child(scene, kind, args.frames, False)
            single = _child(scene, kind, args.frames, True)
            line = (f"  {kind:5s}: {threads * 1e3:6.0f} ms with llvmpipe's threads, "
                    f"{single * 1e3:6.0f} ms in one thread; two-core bound {single * 500:6.0f} ms")
            if args.peer:
                line += f", so peer/frame at most {args.peer[n] / (single * 500):.2f}"
            print(line, flush=True)


if __name__ == "__main__":
    run(main)
