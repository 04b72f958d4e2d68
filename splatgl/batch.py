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

from .camera import Camera
from .frame_output import FrameTarget
from .image_io import write_image
from .progress import ProgressCallback
from .render import Renderer
from .scene import Scene
from .settings import RenderSettings, RendererKind

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
                  kind: RendererKind = RendererKind.QUAD, bit_depth: int = 8,
                  resume: bool = False, fps: float = 30.0,
                  progress: Optional[ProgressCallback] = None,
                  write_queue: int = WRITE_QUEUE, first_frame: int = 0) -> BatchResult:
    """Render ``cameras`` in order to ``target``.

    Image frames are written atomically, so a frame file that exists is complete; with
    ``resume`` those are skipped.  A video is written to a temporary file and renamed when
    complete (removed on any error or interrupt).  ``write_queue`` frames may wait for the
    writer thread while the next renders (0: write in line).  Camera i is written as frame
    ``first_frame + i`` (a worker's contiguous chunk of a longer path).  Frame k is rendered exactly as
    ``splatgl render --camera`` renders the same camera (same renderer call), so the files
    are identical bit for bit.
    """
    from .video import VideoWriter

    target.prepare()
    todo = [k for k in range(len(cameras))
            if not (resume and not target.is_video and target.frame_path(first_frame + k).is_file())]
    skipped = len(cameras) - len(todo)
    meter = FrameMeter(len(cameras), progress)
    render_seconds = 0.0
    t0 = time.perf_counter()
    video = None
    if target.is_video:
        c0 = cameras[0]
        video = VideoWriter(target.video, c0.width, c0.height, fps)

    def save(k: int, out) -> None:
        if video is not None:
            video.write(out)
        elif target.wants_depth:
            write_image(target.frame_path(first_frame + k), out.rgba, bit_depth, depth=out.expected_depth())
        else:
            write_image(target.frame_path(first_frame + k), out, bit_depth)

    # One writer thread encodes frame k while frame k + 1 renders (OpenImageIO and FFmpeg
    # release the GIL); it works in order, and at most ``write_queue`` frames wait for it.
    pending: deque[Future] = deque()
    writer = ThreadPoolExecutor(max_workers=1, thread_name_prefix="splatgl-writer")
    try:
        frames = renderer.render_many(scene, [cameras[k] for k in todo], settings, kind,
                                      depth=target.wants_depth)
        for n, (k, out) in enumerate(zip(todo, frames), 1):
            times = getattr(renderer.renderer_for(scene, settings, kind), "last_times", None) \
                if kind is not RendererKind.REFERENCE else None
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
    return BatchResult(len(todo), skipped, time.perf_counter() - t0, render_seconds)
