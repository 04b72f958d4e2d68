"""``splatgl view --benchmark N``: a scripted orbit through the viewer's own loop, timed."""

from __future__ import annotations

import time
from dataclasses import replace

import glfw
import numpy as np

from ..errors import SplatglError


def orbit_benchmark(viewer, frames: int) -> dict[str, float]:
    """Render ``frames`` frames of a scripted orbit in ``viewer`` (yaw steps of 360 / (frames +
    1) degrees about the start view, so every frame is a new view), each presented, swapped
    and finished; returns mean seconds per frame and per stage, fps (from the mean frame), and
    the median and 10th percentile of the frames' rates (``fps_median``, ``fps_p10``: with a
    frame-time budget, a few slow frames weigh on the mean)."""
    totals = {"frame": 0.0, "sort": 0.0, "draw": 0.0}
    seconds = []
    start = viewer.state
    for i in range(1, frames + 1):
        glfw.poll_events()
        viewer.state = replace(start, yaw=start.yaw + 360.0 * i / (frames + 1))
        t0 = time.perf_counter()
        if not viewer.step(dt=0.0):
            raise SplatglError("benchmark: the window cannot be drawn into (minimised?)")
        viewer.ctx.finish()
        seconds.append(time.perf_counter() - t0)
        totals["frame"] += seconds[-1]
        totals["sort"] += viewer.last.sort
        totals["draw"] += viewer.last.draw
    out = {k: v / frames for k, v in totals.items()}
    out["fps"] = 1.0 / out["frame"]
    rates = 1.0 / np.array(seconds)
    out["fps_median"], out["fps_p10"] = float(np.median(rates)), float(np.percentile(rates, 10))
    viewer.state = start
    return out
