"""Benchmark rows that prove each "skip what the scene doesn't need" saving, as pairs.

- SH: an SH0 scene against the same scene zero-padded to SH3 (padding is what a renderer that
  always stores and evaluates 48 coefficients pays).
- Culling: a view with about 90% of the splats off-screen, culled against not culled, and
  against an all-on-screen view.
- Still camera: the same camera every frame (the sort is reused) against an orbit.
"""

from __future__ import annotations

import dataclasses
import statistics
import time

import numpy as np

from ..camera import Camera
from ..cull import cull
from ..project import to_camera
from ..render import Renderer, default_camera
from ..scene import Scene
from ..settings import RenderSettings, resolve_near
from .runner import BenchOptions, BenchRow, orbit_path


def _time(quad, cameras: list[Camera]) -> tuple[float, float, float, dict]:
    """(median, p10, p90) milliseconds of ``quad.render`` over ``cameras`` after one warm-up,
    and the median of each stage."""
    quad.render(cameras[-1])
    times, stages = [], []
    for cam in cameras:
        t0 = time.perf_counter()
        quad.render(cam)
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


def mostly_offscreen_camera(scene: Scene, options: BenchOptions, target: float = 0.1) -> Camera:
    """The default view moved towards the scene's centre until about ``target`` of the splats
    survive culling (bisection on the distance scale)."""
    settings = RenderSettings()
    lo, hi = 0.01, 1.0
    for _ in range(18):
        mid = (lo * hi) ** 0.5
        frac = visible_fraction(scene, default_camera(scene, options.width, options.height,
                                                      distance_scale=mid), settings)
        lo, hi = (mid, hi) if frac < target else (lo, mid)
    return default_camera(scene, options.width, options.height, distance_scale=hi)


def savings_rows(renderer: Renderer, name: str, scene: Scene, options: BenchOptions,
                 base: RenderSettings = RenderSettings()) -> list[BenchRow]:
    rows = []
    cams = orbit_path(scene, options)

    def quad(s: Scene, settings: RenderSettings):
        return renderer.renderer_for(s, settings)

    # SH: own degree against zero-padded to 3 (only meaningful for scenes below degree 3).
    if scene.sh_degree < 3:
        padded = scene.with_sh_degree(3)
        rows.append(_row(name, scene, f"sh{scene.sh_degree} stored as is", _time(quad(scene, base), cams)))
        rows.append(_row(name, scene, "same scene padded to sh3", _time(quad(padded, base), cams)))

    # Culling: ~90% off-screen, culled and not; and the all-on-screen default view.
    off = mostly_offscreen_camera(scene, options)
    frac = visible_fraction(scene, off, base)
    # Orbit at the close distance: move each orbit pose's eye towards the centre.
    lo, hi = scene.robust_bounds
    centre = 0.5 * (lo + hi)
    scale = float(np.linalg.norm(off.center - centre) / np.linalg.norm(cams[0].center - centre))
    off_path = []
    for c in cams:
        eye = centre + (c.center - centre) * scale
        m = c.world_to_camera.copy()
        m[:3, 3] = -m[:3, :3] @ eye
        off_path.append(c.with_pose(m))
    culled = quad(scene, base)
    rows.append(_row(name, scene, f"{(1 - frac) * 100:.0f}% off-screen, culled", _time(culled, off_path),
                     culled.last_times.drawn if culled.last_times else None))
    unculled = quad(scene, dataclasses.replace(base, cull=False))
    rows.append(_row(name, scene, f"{(1 - frac) * 100:.0f}% off-screen, not culled",
                     _time(unculled, off_path), unculled.last_times.drawn if unculled.last_times else None))
    rows.append(_row(name, scene, "all on-screen (default view)", _time(culled, cams)))

    # Still camera against moving: the still one reuses the sort (and the upload of indices).
    still = quad(scene, base)
    rows.append(_row(name, scene, "moving camera (orbit)", _time(still, cams)))
    rows.append(_row(name, scene, "still camera", _time(still, [cams[0]] * len(cams))))
    return rows
