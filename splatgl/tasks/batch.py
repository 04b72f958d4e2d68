"""Render many views of one scene in one process: one context, the scene uploaded once, the
shaders compiled once; frames written atomically as they come, or encoded into a video.

:func:`render_frames` is what ``splatgl render --path`` runs; :meth:`Renderer.render_many` is
the iterator underneath for Python callers.
"""

from __future__ import annotations

import math
import time
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from typing import Callable, Optional, Sequence

from ..cameras.camera import Camera
from ..imagefiles.frame_record import FrameRecord
from ..imagefiles.frame_targets import FrameTarget, plan_frames
from ..imagefiles.images import write_image
from ..imagefiles.layer_files import write_layers
from ..output.layers import RenderOutput
from ..progress import ProgressCallback
from ..api import Renderer
from ..scene.splats import Scene
from ..scene.settings import RenderSettings, RendererKind
from ..renderers.registry import DEFAULT_RENDERER

#: Frames rendered but not yet written that may wait for the writer thread.
#: 0 writes each frame before the next renders.  Measured on 2 cores (llvmpipe), biker at
#: 1280x720: 2 pending gave 0.44-0.46 s per frame against 0.51 s writing in line.
WRITE_QUEUE = 2


@dataclass(frozen=True)
class BatchResult:
    """What a batch did: frames ``written`` and ``skipped`` (already complete, ``resume``),
    ``seconds`` of wall-clock time for the loop, ``render_seconds`` the sum of the renderer's
    own per-frame stage times (``last_times.total``; 0 where the renderer reports none)."""

    written: int
    skipped: int
    seconds: float
    render_seconds: float
    #: Of ``written``: frame files found damaged (cut short) by ``resume`` and rendered again.
    damaged: int = 0
    #: Of ``skipped``: frames kept without a record of what made them (older splatgl).
    unchecked: int = 0

    @property
    def fps(self) -> float:
        return self.written / self.seconds if self.seconds > 0 else math.inf


def _clock(seconds: float) -> str:
    seconds = int(round(seconds))
    return f"{seconds // 3600}:{seconds // 60 % 60:02d}:{seconds % 60:02d}" if seconds >= 3600 \
        else f"{seconds // 60}:{seconds % 60:02d}"


class FrameMeter:
    """Reports ``frames (F fps, ETA m:ss)`` through a :data:`ProgressCallback` (``unit``
    names what is counted: ``views (F/s, ETA m:ss)``)."""

    def __init__(self, total: int, progress: Optional[ProgressCallback],
                 clock: Callable[[], float] = time.monotonic, unit: str = "frames"):
        self.total, self.progress, self.clock, self.unit = total, progress, clock, unit
        self.start = clock()

    def __call__(self, done: int, rendered: int) -> None:
        """``done`` frames finished of which ``rendered`` were rendered now (not skipped)."""
        if self.progress is None:
            return
        elapsed = self.clock() - self.start
        if rendered > 0 and elapsed > 0:
            fps = rendered / elapsed
            eta = (self.total - done) / fps
            rate = "fps" if self.unit == "frames" else f"{self.unit}/s"
            what = f"{self.unit} ({fps:.2f} {rate}, ETA {_clock(eta)})"
        else:
            what = self.unit
        self.progress(done, self.total, what)


def render_frames(renderer: Renderer, scene: Scene, cameras: Sequence[Camera],
                  settings: RenderSettings, target: FrameTarget,
                  kind: RendererKind = DEFAULT_RENDERER, bit_depth: int = 8,
                  resume: bool = False, fps: float = 30.0,
                  progress: Optional[ProgressCallback] = None,
                  write_queue: int = WRITE_QUEUE, numbers: Optional[Sequence[int]] = None,
                  record: Optional[FrameRecord] = None) -> BatchResult:
    """Render ``cameras`` in order to ``target``.

    Image frames are written atomically and checked, so a frame file is complete or absent;
    with ``resume`` complete ones are kept and damaged ones (cut short, from older versions or
    other programs) rendered again (:func:`splatgl.imagefiles.frame_targets.plan_frames`, which also
    refuses, before any work, frames of another size).  A video is written to a temporary
    file and renamed when complete (removed on any error or interrupt).  ``write_queue``
    frames may wait for the writer thread while the next renders (0: write in line).  Camera
    i is written as frame ``numbers[i]`` (default ``i``: the camera's index in its source, so
    parts of a path rendered apart never collide).  Frame k is rendered exactly as ``splatgl
    render --camera`` renders the same camera (same renderer call), so the files are
    identical bit for bit.  A renderer with a ``frame_size(camera)`` method (stereo: both
    eyes in one frame) makes frames of that size.  ``record``: what the frames are rendered
    from (:mod:`splatgl.imagefiles.frame_record`), written into each frame file, and with
    ``resume`` checked against the frames kept.
    """
    from ..imagefiles.video import VideoWriter

    numbers = list(range(len(cameras))) if numbers is None else list(numbers)
    if len(numbers) != len(cameras):
        raise ValueError(f"{len(numbers)} frame numbers for {len(cameras)} cameras")
    size_of = getattr(renderer, "frame_size", lambda c: (c.width, c.height))
    plan = plan_frames(target, [size_of(c) for c in cameras], numbers, bit_depth, resume, record,
                       cameras)
    target.prepare()
    todo = plan.todo
    skipped = plan.skipped
    meter = FrameMeter(len(cameras), progress)
    render_seconds = 0.0
    t0 = time.perf_counter()
    video = None
    if target.is_video:
        video = VideoWriter(target.video, *size_of(cameras[0]), fps)

    def save(k: int, out) -> None:
        header = record.attributes(cameras[k]) if record is not None else None
        if video is not None:
            video.write(out)
        elif target.layers is not None or target.named:   # --layers alpha: its picture too
            out = out if isinstance(out, RenderOutput) else RenderOutput(out, None)
            write_layers(target.frame_path(numbers[k]), out, target.files(cameras[k]), bit_depth,
                         attributes=header)
        else:
            write_image(target.frame_path(numbers[k]), out, bit_depth, attributes=header)

    # One writer thread encodes frame k while frame k + 1 renders (OpenImageIO and FFmpeg
    # release the GIL); it works in order, and at most ``write_queue`` frames wait for it.
    pending: deque[Future] = deque()
    writer = ThreadPoolExecutor(max_workers=1, thread_name_prefix="splatgl-writer")
    try:
        frames = renderer.render_many(scene, [cameras[k] for k in todo], settings, kind,
                                      layers=target.layers)
        for n, (k, out) in enumerate(zip(todo, frames), 1):
            times = getattr(renderer.renderer_for(scene, settings, kind), "last_times", None)
            render_seconds += times.total if times is not None else 0.0
            while len(pending) >= max(write_queue, 1):
                pending.popleft().result()  # re-raises a failed write
            pending.append(writer.submit(save, k, out))
            if write_queue == 0:
                pending.popleft().result()
            meter(skipped + n - len(pending) + 1, n)
        while pending:
            pending.popleft().result()
    except BaseException:
        # Frames already handed to the writer finish (each is atomic); then the video goes.
        writer.shutdown(wait=True, cancel_futures=True)
        if video is not None:
            video.abort()
        raise
    writer.shutdown(wait=True)
    if video is not None:
        video.close()
    meter(len(cameras), len(todo))
    return BatchResult(len(todo), skipped, time.perf_counter() - t0, render_seconds, plan.damaged,
                       plan.unchecked)
