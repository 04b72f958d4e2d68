"""The first moving frames after a rest: at what level, and at what PSNR, does motion resume?

The viewer rests often (a user drags, lets go, looks, drags again).  This script drives one
:class:`~splatgl.interactive.session.Session` at 1280x720 through ``--cycles`` rounds of
``--moving`` moving frames along the flight's orbit (0.1 s of flight apart, wrapping within its
first 4.5 s) and a rest refined to the exact frame; for the first ``--after`` moving frames
after each rest it prints the level, the draw time and the PSNR against the exact render of
the same camera.

    python benchmarks/interactive_resume.py SCENE [--cycles 5 --moving 12 --after 3]
"""

from __future__ import annotations

import argparse
import math

import numpy as np
from _script import run

from splatgl.api import Renderer, default_settings
from splatgl.measure.bench.flight import Flight
from splatgl.measure.evaluation.metrics import psnr
from splatgl.formats import load_scene
from splatgl.interactive.lod_cache import LodProvider
from splatgl.interactive.session import Session

ORBIT_WRAP = 4.5      # seconds of the flight's orbit the cameras cycle through
STEP = 0.1            # seconds of flight between moving frames


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("scene")
    p.add_argument("--cycles", type=int, default=5, help="rests (default 5)")
    p.add_argument("--moving", type=int, default=12, help="moving frames before each rest (default 12)")
    p.add_argument("--after", type=int, default=3, help="frames scored after each rest (default 3)")
    p.add_argument("--budget", type=float, default=0.1, help="seconds a frame (default 0.1)")
    args = p.parse_args()
    for name in ("cycles", "moving", "after"):
        if getattr(args, name) < 1:
            p.error(f"--{name} must be at least 1, got {getattr(args, name)}")
    if args.after > args.moving:
        p.error(f"--after ({args.after}) cannot exceed --moving ({args.moving})")
    scene = load_scene(args.scene)
    settings = default_settings(scene)
    flight = Flight(scene, 1280, 720)
    scores = []
    with Renderer() as renderer:
        lod = LodProvider(scene, scene.source.path)
        lod.wait()
        session = Session(renderer, scene, settings, args.budget, lod)
        t = 0.0
        try:
            for cycle in range(args.cycles):
                for i in range(args.moving):
                    camera = flight.camera(t)
                    frame = session.frame(camera)
                    t = (t + STEP) % ORBIT_WRAP
                    if cycle > 0 and i < args.after:     # the first frames after a rest
                        exact = renderer.render(scene, camera, settings)
                        score = psnr(session.levels.read(frame)[..., :3], exact[..., :3])
                        scores.append(score)
                        print(f"rest {cycle}, frame {i + 1}: {frame.level.describe()}, "
                              f"{frame.seconds * 1e3:.0f} ms, {score:.1f} dB", flush=True)
                camera = flight.camera(t)
                while session.pending or not session.exact:   # rest: refine to exact
                    session.frame(camera)
                t = (t + STEP) % ORBIT_WRAP
        finally:
            session.release()
    finite = [s for s in scores if math.isfinite(s)]
    print(f"median PSNR of the first {args.after} frames after a rest: {np.median(finite):.1f} dB "
          f"(min {min(finite):.1f}; {len(scores)} frames)")


if __name__ == "__main__":
    run(main)
