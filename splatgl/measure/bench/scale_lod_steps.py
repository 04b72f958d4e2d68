"""The steps of ``splatgl bench --scale --lod`` (:mod:`splatgl.measure.bench.scale_lod`), each run in a
fresh process: ``python -m splatgl.measure.bench.scale_lod_steps STEP JSON`` prints one JSON line with
the step's figures, ``seconds`` (the step's own work, timed inside the process) and
``peak_rss_mb`` (the process's VmHWM at its end: the step's peak resident memory, interpreter
and OpenGL driver included).

Steps:

- ``scene``: the ``splats``-splat PLY written a block of rows at a time (:func:`write_tiled_scene`).
- ``build``: the out-of-core level of detail (:func:`splatgl.lod.external.build_lod_file`) under
  ``memory`` bytes, as ``splatgl lod --memory``.
- ``open``: the ``.lod.ply`` opened lazily (:class:`~splatgl.lod.lazy.LazyLod`) and its framing
  proxy read (what a first frame needs before its cut).
- ``frame``: a cold start's first frame: the whole-scene view (the default camera framing the
  proxy) streamed under ``memory`` (:func:`splatgl.lod.stream_frames.render_streamed`, exact);
  the image saved for the PSNR.
- ``far``: the same from the far view (:data:`FAR` times the framing distance), in its own
  process.
- ``full``: both views at full detail from the PLY loaded whole (only where it fits).
- ``flight``: the interactive flight (:func:`splatgl.measure.bench.flight.fly`, ``bench
  --interactive``'s) over the streamed scene (:class:`splatgl.lod.stream_view.StreamedScene`,
  resident under ``memory``) through the viewer's own session and frame-time budget
  (:func:`splatgl.interactive.stream_levels.streamed_session`, as ``view --memory
  --target-fps 10``): moving frames at the budget's level of what is resident, then at rest
  until the exact frame is drawn with every chunk in; the resident memory, chunks loaded and
  resident set sampled every frame.
"""

from __future__ import annotations

import io
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

from .scale import peak_rss_mb

#: Rows built and written at a time (each block is a grid of copies of the shared scenes).
BLOCK = 1_000_000
#: Seed of the first block (block i uses SEED + i).
SEED = 0


def write_tiled_scene(path: Path, splats: int, block: int = BLOCK, sources=None,
                      shared: Path | None = None) -> int:
    """Write a ``splats``-splat SH0 PLY at ``path`` (atomically), ``block`` rows at a time: block
    i is :func:`splatgl.measure.bench.real_scenes.build_real_scene` (seed ``SEED + i``) moved to cell i
    of a square grid of blocks, so the whole scene is never in memory.  Returns the bytes
    written."""
    from ...formats.ply_write import _header, scene_to_vertices
    from ...writing.atomic import atomic_target
    from .real_scenes import build_real_scene, load_real_sources

    sources = load_real_sources(root=shared) if sources is None else sources
    blocks = math.ceil(splats / block)
    columns = math.ceil(math.sqrt(blocks))
    spacing = None
    with atomic_target(path) as tmp, open(tmp, "wb") as fh:
        for i in range(blocks):
            n = min(block, splats - i * block)
            scene = build_real_scene(n, SEED + i, 0, sources)
            rows = scene_to_vertices(scene)
            if spacing is None:   # the first (full) block's width, plus the copies' gap
                lo, hi = scene.robust_bounds
                spacing = float(max(hi[0] - lo[0], hi[2] - lo[2])) * 1.1 + 1.25
                fh.write(_header([("vertex", splats, rows.dtype)], "little", False,
                                 (f"splatgl bench --scale --lod: {splats} splats",)))
            row, col = divmod(i, columns)
            rows["x"] += np.float32(spacing * (col - (columns - 1) / 2.0))
            rows["z"] += np.float32(spacing * (row - (columns - 1) / 2.0))
            rows.astype(rows.dtype.newbyteorder("<"), copy=False).tofile(fh)
            del scene, rows
    return path.stat().st_size


def _save_image(path: str, image: np.ndarray) -> None:
    from ...writing.atomic import atomic_write_bytes

    buf = io.BytesIO()
    np.save(buf, np.ascontiguousarray(image[..., :3], np.float32))
    atomic_write_bytes(path, buf.getvalue())


#: The far view's distance, in framing distances (``bench --lod``'s far view).
FAR = 6.0
#: The flight's frame rate (the viewer's budget on software GL: ``view --target-fps``'s default
#: there, and the issue's target).
FLIGHT_FPS = 10.0


def _camera(lazy, a: dict, far: bool = False):
    """(framing proxy, camera): the default camera, or the far view (:data:`FAR` times the
    framing distance, as ``bench --lod``'s fly-through starts)."""
    from ...api import default_camera
    from ...cameras.poses import orbit
    from ...lod.stream_frames import framing_scene

    framing = framing_scene(lazy)
    camera = default_camera(framing, a["width"], a["height"])
    if far:
        lo, hi = framing.robust_bounds
        centre = 0.5 * (np.asarray(lo) + np.asarray(hi))
        dist = float(np.linalg.norm(camera.center - centre))
        camera = camera.with_pose(orbit(centre, FAR * dist, 0.0, 20.0))
    return framing, camera


def step_scene(a: dict) -> dict:
    size = write_tiled_scene(Path(a["scene"]), a["splats"], a.get("block", BLOCK),
                             shared=Path(a["shared"]) if a.get("shared") else None)
    return {"file_mb": size / 1e6}


def step_build(a: dict) -> dict:
    from ...lod.budget import plan
    from ...lod.external import build_lod_file

    budget, branching = int(a["memory"]), int(a["branching"])
    info = build_lod_file(Path(a["scene"]), Path(a["lod"]), branching,
                          lambda record, count: plan(budget, branching, record, count))
    return {"lod_mb": Path(a["lod"]).stat().st_size / 1e6,
            **{k: info[k] for k in ("leaves", "parents", "levels", "chunks") if k in info}}


def step_open(a: dict) -> dict:
    from ...lod.lazy import LazyLod

    with LazyLod(a["lod"]) as lazy:
        _camera(lazy, a)
        return {"levels": int(lazy.levels)}


def step_frame(a: dict) -> dict:
    from ...lod.lazy import LazyLod
    from ...lod.selection import LodSettings
    from ...lod.stream_frames import render_streamed
    from ...renderers import auto
    from ...scene.settings import RenderSettings

    with LazyLod(a["lod"]) as lazy:
        framing, camera = _camera(lazy, a, a.get("far", False))
    choice = auto.choose(settings=RenderSettings())   # render --memory's default renderer
    out, times, _ = render_streamed(a["lod"], camera, RenderSettings(), LodSettings(),
                                    int(a["memory"]), framing=framing, kind=choice.kind)
    _save_image(a["image"], out.rgba)
    return {"cut_nodes": int(times.cut_nodes), "streaming": times.streaming,
            "renderer": choice.text()}


#: The path step's arc: frames orbit the framing's centre this many degrees, at the default
#: camera's distance and elevation (every frame a capped whole-scene view, the chunks it needs
#: changing as the view turns).
PATH_ARC = 90.0


def _rss_mb(field: str = "VmRSS") -> float:
    """``field`` of /proc/self/status in MB (kB / 1000, as :func:`~.scale.peak_rss_mb`)."""
    for line in open("/proc/self/status"):
        if line.startswith(field + ":"):
            return int(line.split()[1]) / 1e3
    return 0.0


def _reset_peak() -> bool:
    """Reset this process's peak resident memory (VmHWM; Linux 4.0 on), False where it cannot."""
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
        return True
    except OSError:
        return False


def step_path(a: dict) -> dict:
    """A ``frames``-frame path render streamed under ``memory`` (``render --path --memory``'s
    frames: :class:`~splatgl.lod.stream_frames.StreamFrames`, each exact), the process's peak
    resident memory during each frame (VmHWM, reset before it; where it cannot be reset, the
    resident memory after it): whether it stays flat."""
    from ...cameras.poses import orbit
    from ...lod.lazy import LazyLod
    from ...lod.selection import LodSettings
    from ...lod.stream_frames import StreamFrames
    from ...renderers import auto
    from ...scene.settings import RenderSettings

    with LazyLod(a["lod"]) as lazy:
        framing, camera = _camera(lazy, a)
    lo, hi = framing.robust_bounds
    centre = 0.5 * (np.asarray(lo) + np.asarray(hi))
    offset = camera.center - centre
    dist = float(np.linalg.norm(offset))
    elevation = float(np.degrees(np.arcsin(-offset[1] / dist)))   # orbit's up is -y
    start = float(np.degrees(np.arctan2(-offset[0], offset[2])))   # its azimuth 0 is +z
    n = int(a["frames"])
    cameras = [camera.with_pose(orbit(centre, dist, start + PATH_ARC * i / max(1, n - 1),
                                      elevation)) for i in range(n)]
    choice = auto.choose(settings=RenderSettings())
    rss, seconds = [], []
    before = peak_rss_mb()   # the peaks are reset below: the step's own is their largest
    with StreamFrames(a["lod"], RenderSettings(), LodSettings(), int(a["memory"]),
                      framing=framing, kind=choice.kind) as frames:
        for cam in cameras:
            peak = _reset_peak()
            t0 = time.perf_counter()
            frames.render_view(cam)
            seconds.append(time.perf_counter() - t0)
            rss.append(_rss_mb("VmHWM" if peak else "VmRSS"))
        summary = frames.summary()
    before = max(before, peak_rss_mb())   # opening and closing (or all, where not reset)
    half = max(1, n // 2)
    return {"frames": n, "frame_s_median": float(np.median(seconds)), "rss_mb": rss,
            "rss_is": "peak during each frame" if peak else "resident after each frame",
            "rss_first_mb": rss[0], "rss_last_mb": rss[-1], "rss_max_mb": max(rss),
            "rss_max_first_half_mb": max(rss[:half]),
            "rss_max_second_half_mb": max(rss[half:] or rss),
            "streaming": summary, "renderer": choice.text(),
            "peak_rss_mb": max([before, *rss])}


def step_full(a: dict) -> dict:
    from ...api import Renderer
    from ...formats import load_scene
    from ...lod.lazy import LazyLod
    from ...scene.settings import RenderSettings

    with LazyLod(a["lod"]) as lazy:
        cameras = [_camera(lazy, a, far)[1] for far in (False, True)]
    scene = load_scene(a["scene"], progress=lambda *x: None)
    with Renderer() as renderer:
        for camera, image in zip(cameras, (a["image"], a["far_image"])):
            _save_image(image, renderer.render(scene, camera, RenderSettings()))
    return {}


def step_flight(a: dict) -> dict:
    from ...api import Renderer
    from ...lod.selection import LodSettings
    from ...lod.stream_view import StreamedScene

    streamed = StreamedScene(a["lod"], LodSettings(), int(a["memory"]))
    try:
        with Renderer() as renderer:
            return flight(renderer, streamed, a)
    finally:
        streamed.close()


def flight(renderer, streamed, a: dict) -> dict:
    """The ``flight`` step's figures: :func:`~.flight.fly` over ``streamed`` (a
    :class:`~splatgl.lod.stream_view.StreamedScene`) at ``a``'s ``width``, ``height``,
    ``speed`` and ``target_fps`` (default :data:`FLIGHT_FPS`)."""
    from .flight import fly

    result = fly(renderer, None, streamed.lazy.path.name, a["width"], a["height"],
                 a.get("target_fps", FLIGHT_FPS), log=lambda m: None, speed=a.get("speed", 1.0),
                 stream=streamed)
    summary = streamed.summary()
    s = result.summary()
    frames = [f.seconds for f in result.frames]
    return {"moving_frames": len(frames), "fps_median": s["fps_median"] if frames else None,
            "fps_p10": s["fps_p10"] if frames else None,
            "frame_ms_median": 1e3 * float(np.median(frames)) if frames else None,
            "target_fps": result.target_fps,
            "rest_to_exact_s": s["rest_to_exact"] if result.reached_exact else None,
            "reached_exact": result.reached_exact, "rest_frames": len(result.refine_steps),
            "exact_frame_s": s["exact_seconds"],
            "levels": _levels(result), "streaming": summary, "capped": streamed.capped,
            "cache_mb": streamed.plan.cache / 1e6, "frame_cap": streamed.plan.cap,
            **{k: s[k] for k in ("resident_max_mb", "chunks_loaded", "rss_start_mb",
                                 "rss_end_mb", "rss_max_mb")},
            "samples": result.samples}


def _levels(result) -> dict:
    """How often each level drew a moving frame (``"scale 0.50, <= 100,000 splats": count``)."""
    from ...interactive.budget import Level

    counts: dict = {}
    for f in result.frames:
        name = Level(f.scale, f.budget, f.sh_degree).describe()
        counts[name] = counts.get(name, 0) + 1
    return counts


STEPS = {"scene": step_scene, "build": step_build, "open": step_open, "frame": step_frame,
         "far": step_frame, "full": step_full, "flight": step_flight, "path": step_path}


def main(argv: list[str]) -> int:
    step, args = argv[0], json.loads(argv[1])
    t0 = time.perf_counter()
    result = STEPS[step](args)
    result.update(seconds=time.perf_counter() - t0, pid=os.getpid(),
                  peak_rss_mb=max(peak_rss_mb(), result.get("peak_rss_mb", 0.0)))
    print(json.dumps(result), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
