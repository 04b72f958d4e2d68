"""Would two GL contexts, each drawing half of the frame, make an exact frame cheaper?

llvmpipe runs its vertex processing and triangle setup in the thread that draws, and only the
rasterisation in its own threads, so one idea for same-work speed on a 2-core machine is to
split the frame between two processes (left and right halves, each its own context) and let
both front ends run at once.  This script measures whether that can pay at all, with
``Renderer.render`` (the exact frame, readback included) along the start of the interactive
flight's orbit (:class:`splatgl.measure.bench.flight.Flight`) at 1280x720:

- ``full``: one process draws whole frames;
- ``halves``: two processes draw the left and right halves at the same time (the camera's
  principal point shifted by half the width), each timing its own frames;
- ``one thread``: whole frames with ``LP_NUM_THREADS=0`` (llvmpipe rasterises in the drawing
  thread): against ``full``, how much of the frame llvmpipe already spreads over the cores.

If the halves, run together, take about as long as a whole frame alone, the frame already keeps
the machine's cores busy and splitting it cannot pay.

    python benchmarks/split_frame.py SCENE [--frames 15]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time

import numpy as np
from _script import run

WIDTH, HEIGHT = 1280, 720
#: Seconds of the flight's orbit between timed frames (1.8 degrees).
ORBIT_STEP = 0.05


def _frames(scene_path: str, part: str, frames: int) -> float:
    """Median seconds of ``frames`` exact frames of ``part`` ("full", "left" or "right")."""
    import dataclasses

    import splatgl
    from splatgl.measure.bench.flight import Flight

    scene = splatgl.load_scene(scene_path)
    flight = Flight(scene, WIDTH, HEIGHT)

    def camera(i: int):
        full = flight.camera(ORBIT_STEP * i)   # the flight's orbit: every frame a new view
        if part == "full":
            return full
        shift = 0 if part == "left" else WIDTH // 2
        return dataclasses.replace(full, width=WIDTH // 2, cx=full.cx - shift)

    with splatgl.Renderer() as renderer:
        renderer.render(scene, camera(0))   # compile and upload, untimed
        seconds = []
        for i in range(frames):
            t = time.perf_counter()
            renderer.render(scene, camera(i))
            seconds.append(time.perf_counter() - t)
    return float(np.median(seconds))


def _spawn(scene: str, part: str, frames: int, env: dict | None = None) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, __file__, scene, "--frames", str(frames), "--part", part],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)


def _result(proc: subprocess.Popen) -> float:
    out, err = proc.communicate()
    if proc.returncode != 0:
        last = err.strip().splitlines()[-1] if err.strip() else f"exit {proc.returncode}"
        raise SystemExit(f"split_frame.py: a timing process failed: {last}")
    return float(out.strip().splitlines()[-1])


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("scene")
    p.add_argument("--frames", type=int, default=15, help="timed frames per process (default 15)")
    p.add_argument("--part", choices=("full", "left", "right"), help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.frames < 1:
        p.error(f"--frames must be at least 1, got {args.frames}")
    if not os.path.isfile(args.scene):
        p.error(f"no such scene file: {args.scene}")
    if args.part is not None:                # a child: time one part, print its median
        print(_frames(args.scene, args.part, args.frames), flush=True)
        return
    full = _result(_spawn(args.scene, "full", args.frames))
    left, right = _spawn(args.scene, "left", args.frames), _spawn(args.scene, "right", args.frames)
    halves = (_result(left), _result(right))
    one_thread = _result(_spawn(args.scene, "full", args.frames, {**os.environ, "LP_NUM_THREADS": "0"}))
    print(f"{os.path.basename(args.scene)} at {WIDTH}x{HEIGHT}, medians of {args.frames} frames:")
    print(f"  full frame, one process:         {full * 1e3:7.1f} ms")
    print(f"  halves, two processes together:  {halves[0] * 1e3:7.1f} / {halves[1] * 1e3:.1f} ms "
          f"(slower half / full: {max(halves) / full:.2f})")
    print(f"  full frame, LP_NUM_THREADS=0:    {one_thread * 1e3:7.1f} ms "
          f"(x{one_thread / full:.2f} the full frame)")


if __name__ == "__main__":
    run(main)
