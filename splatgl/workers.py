"""``--workers N``: render a frame list in N local processes, each with its own headless
context and its own copy of the scene, in contiguous chunks (neighbouring cameras keep the
depth order similar, so each worker's sort stays warm).

Each worker runs :func:`splatgl.batch.render_frames` on its chunk, writing frames under their
global numbers, so the files are the same, frame by frame, as a single-process render.  Workers
report each finished frame on a queue; the parent shows one progress line for all of them.
Video output is not sharded (render frames, or use one process).
"""

from __future__ import annotations

import multiprocessing as mp
import os
import queue
import signal
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Sequence

from .batch import BatchResult, FrameMeter
from .camera import Camera
from .errors import SplatglError
from .frame_output import FrameTarget
from .progress import ProgressCallback
from .settings import RenderSettings, RendererKind


def chunks(count: int, workers: int) -> list[range]:
    """``workers`` contiguous, near-equal ranges covering ``range(count)`` (empty ones dropped)."""
    bounds = [round(i * count / workers) for i in range(workers + 1)]
    return [range(a, b) for a, b in zip(bounds, bounds[1:]) if b > a]


@dataclass(frozen=True)
class ChunkJob:
    """One worker's (or Ray task's) share of a path: cameras ``first_frame ..``, the scene file
    and how to render and write them."""

    scene_path: Path
    drop_invalid: bool
    cameras: tuple[Camera, ...]
    first_frame: int
    settings: RenderSettings
    target: FrameTarget
    kind: RendererKind
    bit_depth: int
    resume: bool


def _worker(job: ChunkJob, messages) -> None:
    from .batch import render_frames
    from .formats import load_scene
    from .render import Renderer

    try:
        scene = load_scene(job.scene_path, drop_invalid=job.drop_invalid, progress=lambda *a: None)
        with Renderer() as renderer:
            result = render_frames(renderer, scene, job.cameras, job.settings, job.target, job.kind,
                                   job.bit_depth, job.resume,
                                   progress=lambda done, total, what: messages.put(("frame", (job.first_frame, done))),
                                   first_frame=job.first_frame)
        messages.put(("done", (result.written, result.skipped, result.seconds, result.render_seconds)))
    except SplatglError as exc:
        messages.put(("error", str(exc)))
    except KeyboardInterrupt:
        messages.put(("interrupted", None))
    except BaseException as exc:  # noqa: BLE001 - reported to the parent, which raises
        messages.put(("error", f"worker {os.getpid()} failed: {type(exc).__name__}: {exc}"))


def render_frames_parallel(scene_path: Path, cameras: Sequence[Camera], settings: RenderSettings,
                           target: FrameTarget, workers: int, kind: RendererKind = RendererKind.QUAD,
                           bit_depth: int = 8, resume: bool = False, drop_invalid: bool = False,
                           progress: Optional[ProgressCallback] = None) -> BatchResult:
    """Render ``cameras`` to image ``target`` in ``workers`` spawned processes.

    Returns the summed :class:`BatchResult` (``seconds`` is the parent's wall time).
    Ctrl-C / SIGTERM interrupts every worker (SIGINT), which finish or drop the frame in hand
    atomically; the parent then re-raises.
    """
    if target.is_video:
        raise SplatglError("--workers renders image frames; write a video with one process")
    if workers < 1:
        raise SplatglError(f"--workers must be at least 1, got {workers}")
    target.prepare()
    ctx = mp.get_context("spawn")  # a fresh interpreter per worker: no inherited GL state
    messages = ctx.Queue()
    procs = []
    t0 = time.perf_counter()
    for part in chunks(len(cameras), workers):
        job = ChunkJob(Path(scene_path), drop_invalid, tuple(cameras[i] for i in part), part.start, settings,
                   target, kind, bit_depth, resume)
        p = ctx.Process(target=_worker, args=(job, messages), daemon=True)
        p.start()
        procs.append(p)
    meter = FrameMeter(len(cameras), progress)
    per_worker: dict[int, int] = {}
    totals = [0, 0, 0.0, 0.0]
    finished = 0
    error = None
    try:
        while finished < len(procs):
            try:
                kind_, payload = messages.get(timeout=0.5)
            except queue.Empty:
                if all(not p.is_alive() for p in procs):
                    raise SplatglError("a worker process died without reporting (killed?); "
                                       "re-run with --resume to finish the missing frames") from None
                continue
            if kind_ == "frame":
                first, count = payload
                per_worker[first] = count
                done = sum(per_worker.values())
                meter(done, done)
            elif kind_ == "done":
                finished += 1
                for i, v in enumerate(payload):
                    totals[i] += v
            else:
                finished += 1
                error = error or (payload if kind_ == "error" else None)
                if kind_ == "interrupted":
                    raise KeyboardInterrupt
        if error:
            raise SplatglError(error)
    except BaseException:
        for p in procs:
            if p.is_alive() and p.pid is not None:
                os.kill(p.pid, signal.SIGINT)  # unwinds like Ctrl-C: no half-written frame
        for p in procs:
            p.join(timeout=30)
        raise
    for p in procs:
        p.join()
    return BatchResult(int(totals[0]), int(totals[1]), time.perf_counter() - t0, totals[3])
