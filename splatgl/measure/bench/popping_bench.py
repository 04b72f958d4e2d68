"""``splatgl bench --popping``: popping along camera paths, the global order against the per-pixel
order, on the quad path, the tile renderer and the reference (docs/fidelity.md).

For each scene, three paths of small steps, as an animation takes them: ``orbit`` (ORBIT_DEGREES
a frame around the scene's robust centre at the framing distance), ``fly`` (towards the centre
from FLY_FROM to FLY_TO times the framing distance, turning FLY_DEGREES a frame) and ``turn`` (a
camera at TURN_DISTANCE times the framing distance turning in place, TURN_DEGREES of yaw a frame
about its own centre: nothing moves in the world and nothing is disoccluded, so a renderer whose
pixels depend only on their rays draws the same world-fixed picture; the global order, sorting
by view z, reorders overlapping splats as the view direction swings).  Each
configuration renders every frame with colour, alpha and depth; the popping metric
(:mod:`splatgl.measure.evaluation.popping`) scores each consecutive pair.  A row: the per-pair
distribution (median, 90th percentile and largest score and popped share, the largest coherent
share), the median frame
time, and for a per-pixel order the PSNR of its first frame against the same renderer's global
order (what the order changes in a still image).
"""

from __future__ import annotations

import statistics
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...api import Renderer, default_camera
from ...cameras.poses import orbit
from ...cameras.up import resolve_up
from ..evaluation.metrics import psnr
from ..evaluation.popping import Frame, default_metric, distribution, popping
from ...errors import SplatglError
from ...scene.settings import DEFAULT_ORDER_WINDOW, MAX_ORDER_WINDOW, Order, RendererKind, RenderSettings
from ...renderers.registry import entry

#: Orbit step (degrees per frame) and the fly-through's distances (multiples of the framing
#: distance) and turn per frame.
ORBIT_DEGREES = 0.5
FLY_FROM, FLY_TO, FLY_DEGREES = 1.2, 0.6, 0.2
TURN_DISTANCE, TURN_DEGREES, TURN_ELEVATION = 0.5, 2.0, 15.0
#: Configurations: name -> (renderer, order).
CONFIGS = {
    "quad": (RendererKind.QUAD, Order.GLOBAL),
    "tile": (RendererKind.TILE, Order.GLOBAL),
    "tile per-pixel": (RendererKind.TILE, Order.PER_PIXEL),
    "reference": (RendererKind.REFERENCE, Order.GLOBAL),
    "reference per-pixel": (RendererKind.REFERENCE, Order.PER_PIXEL),
}
#: The shared scenes measured without scene files (relative to the shared folder), with the up
#: axis each is shown with (None: the scene's own, from its training cameras or -y).
SCENES = (("ply/donut_sh0.ply", "+z"), ("compressed_ply/biker.compressed.ply", None),
          ("compressed_ply/guitar.compressed.ply", None))


#: Frames a path needs at the least: the metric scores pairs of consecutive frames.
MIN_FRAMES = 2


@dataclass(frozen=True)
class PoppingOptions:
    """What :func:`measure_scene` measures; refused in one line, before any work, where it
    could measure nothing (fewer than :data:`MIN_FRAMES` frames: no pair to score) or a window
    the tile renderer does not have."""

    width: int = 640
    height: int = 360
    frames: int = 16
    window: int = DEFAULT_ORDER_WINDOW
    configs: tuple[str, ...] = tuple(CONFIGS)
    metric: str | None = None
    paths: tuple[str, ...] = ("orbit", "fly", "turn")

    def __post_init__(self) -> None:
        if int(self.frames) != self.frames or self.frames < MIN_FRAMES:
            raise SplatglError(f"--frames {self.frames}: --popping scores pairs of consecutive "
                               f"frames, so a path needs at least {MIN_FRAMES}")
        if int(self.window) != self.window or not 1 <= self.window <= MAX_ORDER_WINDOW:
            raise SplatglError(f"--popping-window must be 1..{MAX_ORDER_WINDOW}, got {self.window}")
        unknown = [c for c in self.configs if c not in CONFIGS]
        if unknown or not self.configs:
            what = f"unknown {', '.join(unknown)}" if unknown else "none given"
            raise SplatglError(f"--popping-configs: {what}; valid: {', '.join(CONFIGS)}")


def turned(camera, degrees: float):
    """``camera`` turned in place: yaw of ``degrees`` about its own centre (its y axis)."""
    a = np.radians(degrees)
    yaw = np.array([[np.cos(a), 0.0, np.sin(a)], [0.0, 1.0, 0.0], [-np.sin(a), 0.0, np.cos(a)]])
    w2c = np.array(camera.world_to_camera, float)
    w2c[:3, :3], w2c[:3, 3] = yaw @ w2c[:3, :3], yaw @ w2c[:3, 3]
    return camera.with_pose(w2c)


def camera_paths(scene, path: Path | None, up: str | None, width: int, height: int, frames: int,
                 names=("orbit", "fly", "turn"), turn=(TURN_DISTANCE, TURN_DEGREES)) -> dict[str, list]:
    """{name: [Camera]}: the orbit, the fly-through and the turn (module doc); ``turn`` =
    (distance multiple, degrees a frame)."""
    up_vec, _ = resolve_up(up, path)
    base = default_camera(scene, width, height, up=up_vec)
    centre = 0.5 * (scene.robust_bounds[0] + scene.robust_bounds[1])
    dist = float(np.linalg.norm(base.center - centre))
    at = lambda m, deg, elev=20.0: base.with_pose(orbit(centre, dist * m, deg, elev, up=up_vec))  # noqa: E731
    span = max(frames - 1, 1)
    out = {"orbit": [at(1.0, ORBIT_DEGREES * i) for i in range(frames)],
           "fly": [at(FLY_FROM * (FLY_TO / FLY_FROM) ** (i / span), FLY_DEGREES * i) for i in range(frames)],
           "turn": [turned(at(turn[0], 0.0, TURN_ELEVATION), turn[1] * (i - frames // 2))
                    for i in range(frames)]}
    return {k: v for k, v in out.items() if k in names}


def render_frames(renderer: Renderer, scene, cameras, settings: RenderSettings,
                  kind: RendererKind) -> tuple[list[Frame], list[float]]:
    """Every camera's frame (colour, expected depth, alpha) and its render time (seconds)."""
    frames, times = [], []
    if entry(kind).warms_up:
        renderer.render(scene, cameras[0], settings, kind)        # warm-up: compile, upload
    for cam in cameras:
        t0 = time.perf_counter()
        out = renderer.render_layers(scene, cam, settings, kind)
        times.append(time.perf_counter() - t0)
        frames.append(Frame(out.rgba[..., :3], out.expected_depth(), out.alpha, cam))
    return frames, times


def measure_scene(renderer: Renderer, name: str, scene, path: Path | None, up: str | None,
                  options: PoppingOptions, log=print) -> list[dict]:
    """The rows of one scene (module doc)."""
    metric = options.metric or default_metric()
    rows = []
    for pname, cams in camera_paths(scene, path, up, options.width, options.height,
                                    options.frames, options.paths).items():
        firsts: dict[tuple, np.ndarray] = {}
        for config in options.configs:
            kind, order = CONFIGS[config]
            settings = RenderSettings(order=order, order_window=options.window)
            frames, times = render_frames(renderer, scene, cams, settings, kind)
            firsts[(kind, order)] = frames[0].rgb
            row = {"scene": name, "path": pname, "config": config, "renderer": kind.value,
                   "order": order.value, "window": options.window if kind is RendererKind.TILE
                   and order is Order.PER_PIXEL else None, "metric": metric,
                   "frames": len(frames), "ms_per_frame": 1e3 * statistics.median(times),
                   **distribution(popping(frames, metric))}
            if order is Order.PER_PIXEL and (kind, Order.GLOBAL) in firsts:
                row["still_psnr_vs_global"] = psnr(frames[0].rgb, firsts[(kind, Order.GLOBAL)])
            rows.append(row)
            log(f"  {name} {pname} {config}: popped median {row['popped_median'] * 100:.3f}% "
                f"p90 {row['popped_p90'] * 100:.3f}%, coherent max {row['coherent_max'] * 100:.3f}%, "
                f"score median {row['score_median']:.4f}, {row['ms_per_frame']:.0f} ms/frame")
    return rows


def table(rows: list[dict]) -> str:
    """The rows as a text table."""
    head = (f"{'scene':<24} {'path':<6} {'config':<20} {'popped med':>10} {'p90':>8} {'max':>8} "
            f"{'coh. max':>8} {'score med':>9} {'p90':>7} {'ms/frame':>9} {'still dB':>8}")
    out = [head, "-" * len(head)]
    for r in rows:
        still = r.get("still_psnr_vs_global")
        out.append(f"{r['scene'][:24]:<24} {r['path']:<6} {r['config']:<20} "
                   f"{r['popped_median'] * 100:>9.3f}% {r['popped_p90'] * 100:>7.3f}% "
                   f"{r['popped_max'] * 100:>7.3f}% {r['coherent_max'] * 100:>7.3f}% "
                   f"{r['score_median']:>9.4f} {r['score_p90']:>7.4f} "
                   f"{r['ms_per_frame']:>9.0f} {('' if still is None else f'{still:.1f}'):>8}")
    return "\n".join(out)
