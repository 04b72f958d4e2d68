"""``splatgl view --benchmark N``: a scripted orbit through the viewer's own loop, timed."""

from __future__ import annotations

import time
from dataclasses import replace

import glfw

from ..errors import SplatglError


def orbit_benchmark(viewer, frames: int) -> dict[str, float]:
    """Render ``frames`` frames of a scripted orbit in ``viewer`` (yaw steps of 360 / (frames +
    1) degrees about the start view, so every frame is a new view), each presented, swapped
    and finished; returns mean seconds per frame and per stage, and fps."""
    totals = {"frame": 0.0, "sort": 0.0, "draw": 0.0}
    start = viewer.state
    for i in range(1, frames + 1):
        glfw.poll_events()
        viewer.state = replace(start, yaw=start.yaw + 360.0 * i / (frames + 1))
        t0 = time.perf_counter()
        if not viewer.step(dt=0.0):
            raise SplatglError("benchmark: the window cannot be drawn into (minimised?)")
        viewer.ctx.finish()
        totals["frame"] += time.perf_counter() - t0
        totals["sort"] += viewer.last.sort
        totals["draw"] += viewer.last.draw
    out = {k: v / frames for k, v in totals.items()}
    out["fps"] = 1.0 / out["frame"]
    viewer.state = start
    return out
