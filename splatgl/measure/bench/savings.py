"""Benchmark rows that prove each "skip what the scene doesn't need" saving, as pairs.

- SH: an SH0 scene against the same scene zero-padded to SH3 (padding is what a renderer that
  always stores and evaluates 48 coefficients pays).
- Culling: the orbit turned sideways until about 90% of the splats are off-screen, culled
  against not culled, and against the all-on-screen orbit.
- Still camera: the same camera every frame (the sort is reused) against an orbit.
"""

from __future__ import annotations

import dataclasses
import statistics
import time

import numpy as np

from ...cameras.camera import Camera
from ...order.cull import cull
from ...cameras.view import View
from ...splatmath.project import to_camera
from ...api import Renderer
from ...scene.splats import Scene
from ...scene.settings import Preprocess, RenderSettings, resolve_near
from .runner import BenchOptions, BenchRow, orbit_path


def _time(quad, cameras: list[Camera]) -> tuple[float, float, float, dict]:
    """(median, p10, p90) milliseconds of ``quad.render`` over ``cameras`` after one warm-up,
    and the median of each stage."""
    views = [View.of(cam, quad.options, quad.scene) for cam in cameras]
    quad.render(views[-1])
    times, stages = [], []
    for view in views:
        t0 = time.perf_counter()
        quad.render(view)
        times.append((time.perf_counter() - t0) * 1e3)
        stages.append({k: v * 1e3 for k, v in vars(quad.last_times).items() if isinstance(v, float)})
    med_stages = {k: statistics.median(s[k] for s in stages) for k in stages[0]}
    return statistics.median(times), float(np.percentile(times, 10)), float(np.percentile(times, 90)), med_stages


def _row(name: str, scene: Scene, config: str, stats, drawn: int | None = None) -> BenchRow:
    med, p10, p90, stages = stats
    return BenchRow(name, scene.count, config, "savings", "quad", med, p10, p90, stages, drawn=drawn)


def visible_fraction(scene: Scene, camera: Camera, settings: RenderSettings) -> float:
    near = resolve_near(settings, scene.robust_radius)
    keep = cull(to_camera(scene.means, camera), scene.scales.max(axis=1), scene.opacities, camera, near)
    return float(keep.mean())


def _turned(camera: Camera, degrees: float) -> Camera:
    """The camera turned about its own vertical axis by ``degrees`` (it looks to the side)."""
    a = np.radians(degrees)
    turn = np.eye(4)
    turn[0, 0], turn[0, 2], turn[2, 0], turn[2, 2] = np.cos(a), -np.sin(a), np.sin(a), np.cos(a)
    return camera.with_pose(turn @ camera.world_to_camera)


def mostly_offscreen_camera(camera: Camera, scene: Scene, target: float = 0.1) -> tuple[Camera, float]:
    """``camera`` turned sideways until about ``target`` of the splats survive culling
    (bisection on the angle); returns the camera and the angle in degrees.  Turning, unlike
    moving closer, keeps the visible splats' screen size, so the row isolates what culling
    saves rather than adding fill."""
    settings = RenderSettings()
    lo, hi = 0.0, 90.0
    for _ in range(20):
        mid = 0.5 * (lo + hi)
        frac = visible_fraction(scene, _turned(camera, mid), settings)
        lo, hi = (lo, mid) if frac < target else (mid, hi)
    return _turned(camera, hi), hi


def savings_rows(renderer: Renderer, name: str, scene: Scene, options: BenchOptions,
                 base: RenderSettings = RenderSettings()) -> list[BenchRow]:
    rows = []
    cams = orbit_path(scene, options)

    def quad(s: Scene, settings: RenderSettings):
        return renderer.renderer_for(s, settings)

    # SH: own degree against zero-padded to 3 (only meaningful for scenes below degree 3).
    # Both places the SH math can run: the pre-pass evaluates it once per splat, the vertex
    # stage once per quad corner (4x), so padding costs the latter far more.
    if scene.sh_degree < 3:
        padded = scene.with_sh_degree(3)
        for pre in (base.preprocess, *(p for p in Preprocess if p is not base.preprocess)):
            settings = dataclasses.replace(base, preprocess=pre)
            rows.append(_row(name, scene, f"sh{scene.sh_degree} as stored ({pre.value})",
                             _time(quad(scene, settings), cams)))
            rows.append(_row(name, scene, f"padded to sh3 ({pre.value})", _time(quad(padded, settings), cams)))

    # Culling: ~90% off-screen (the orbit turned sideways), culled and not; and all on-screen.
    off_path = [mostly_offscreen_camera(c, scene)[0] for c in cams]
    frac = float(np.mean([visible_fraction(scene, c, base) for c in off_path]))
    culled = quad(scene, base)
    rows.append(_row(name, scene, f"{(1 - frac) * 100:.0f}% off-screen, culled", _time(culled, off_path),
                     culled.last_times.drawn if culled.last_times else None))
    unculled = quad(scene, dataclasses.replace(base, cull=False))
    rows.append(_row(name, scene, f"{(1 - frac) * 100:.0f}% off-screen, not culled",
                     _time(unculled, off_path), unculled.last_times.drawn if unculled.last_times else None))
    rows.append(_row(name, scene, "all on-screen (default view)", _time(culled, cams),
                     culled.last_times.drawn if culled.last_times else None))

    # Still camera against moving: the still one reuses the sort (and the upload of indices).
    still = quad(scene, base)
    rows.append(_row(name, scene, "moving camera (orbit)", _time(still, cams)))
    rows.append(_row(name, scene, "still camera", _time(still, [cams[0]] * len(cams))))
    return rows
