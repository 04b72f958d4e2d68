"""Would two GL contexts, each drawing half of the frame, make an exact frame cheaper?

llvmpipe runs its vertex processing and triangle setup in the thread that draws, and only the
rasterisation in its own threads, so one idea for same-work speed on a 2-core machine is to
split the frame between two processes (left and right halves, each its own context) and let
both front ends run at once.  This script measures whether that can pay at all, with
``Renderer.render`` (the exact frame, readback included) along a small orbit at 1280x720:

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
import math
import os
import subprocess
import sys
import time

import numpy as np

WIDTH, HEIGHT = 1280, 720


def _frames(scene_path: str, part: str, frames: int) -> float:
    """Median seconds of ``frames`` exact frames of ``part`` ("full", "left" or "right")."""
    import splatgl
    from splatgl.cameras.camera import Camera

    scene = splatgl.load_scene(scene_path)
    base = splatgl.default_camera(scene, WIDTH, HEIGHT)

    def camera(i: int) -> Camera:
        a = math.radians(2.0 * i)           # a small orbit: every frame is a new view
        turn = np.array([[math.cos(a), 0, math.sin(a), 0], [0, 1, 0, 0],
                         [-math.sin(a), 0, math.cos(a), 0], [0, 0, 0, 1.0]])
        pose = base.world_to_camera @ turn
        if part == "full":
            return Camera(WIDTH, HEIGHT, base.fx, base.fy, base.cx, base.cy, pose, base.model)
        shift = 0 if part == "left" else WIDTH // 2
        return Camera(WIDTH // 2, HEIGHT, base.fx, base.fy, base.cx - shift, base.cy, pose, base.model)

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
                            stdout=subprocess.PIPE, text=True, env=env)


def _result(proc: subprocess.Popen) -> float:
    out, _ = proc.communicate()
    if proc.returncode != 0:
        raise SystemExit(f"split_frame: a child process failed (exit {proc.returncode})")
    return float(out.strip().splitlines()[-1])


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("scene")
    p.add_argument("--frames", type=int, default=15, help="timed frames per process (default 15)")
    p.add_argument("--part", choices=("full", "left", "right"), help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.frames < 1:
        p.error(f"--frames must be at least 1, got {args.frames}")
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
    main()
