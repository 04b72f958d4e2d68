"""A camera path's frames rendered by several processes or machines (``render --path`` with
``--workers N`` or ``--executor ray``), as tasks of :mod:`splatgl.tasks.task`.

Each :class:`RenderChunk` renders a contiguous run of the path with
:func:`splatgl.tasks.batch.render_frames`, writing frames under their global numbers, so the files
equal a single-process render's frame by frame.

A video output is assembled once all frames exist: the workers write 8-bit PNG frames to a
hidden folder beside the video (``.NAME.mp4.frames/``), quantised exactly as the video writer
quantises (``clip(rgb) * 255 + 0.5``, truncated), so the encoder sees the same pixels as in a
single-process run; then this process encodes them with :class:`splatgl.imagefiles.video.VideoWriter`
(temporary file renamed when complete) and deletes the folder.  If anything fails or is
interrupted the folder stays (the command names it: :func:`stopped_note`; a folder
without a complete frame is removed), no video is written, and ``--resume`` renders only the
frames still missing before encoding.
"""

from __future__ import annotations

import math
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Sequence

from .batch import BatchResult, FrameMeter
from .task import Done, Files, TaskProgress
from ..cameras.camera import Camera
from .executor import Executor, ExecutorKind, RunResult, run_tasks
from ..imagefiles.frame_record import FrameRecord
from ..imagefiles.frame_targets import FrameTarget, plan_frames
from ..lod.selection import LodSettings
from ..progress import ProgressCallback
from ..scene.settings import RenderSettings, RendererKind
from ..renderers.registry import DEFAULT_RENDERER
from .local import chunks
from .ray import MAX_CHUNK_FRAMES

#: What a failed sharded render tells the user.
RESUME_HINT = "re-run with --resume to render the missing frames"


@dataclass(frozen=True)
class RenderChunk:
    """Cameras of a path written as frames ``numbers``: the scene file and how to render and
    write them."""

    scene_path: Path
    drop_invalid: bool
    cameras: tuple[Camera, ...]
    numbers: tuple[int, ...]
    settings: RenderSettings
    target: FrameTarget
    kind: RendererKind
    bit_depth: int
    resume: bool
    #: Render the scene (a .lod.ply) through this cut (``render --lod-*``); None: full detail.
    lod: Optional[LodSettings] = None
    #: What the frames are rendered from, written into each (``--resume`` checks it).
    record: Optional[FrameRecord] = None

    @property
    def units(self) -> int:
        return len(self.cameras)

    def inputs(self) -> tuple[Path, ...]:
        return (self.scene_path,)

    def label(self) -> str:
        return f"frames {self.numbers[0]}-{self.numbers[-1]}"

    def run(self, files: Files, report: TaskProgress) -> Done:
        from .batch import render_frames
        from ..api import Renderer

        if self.lod is not None:
            from ..lod.frames import LodFrames
            from ..lod.io import read_lod

            with files.local(self.scene_path) as local:
                tree = read_lod(local)
            scene, renderer = None, LodFrames(tree, self.settings, self.lod)
        else:
            scene, renderer = files.load_scene(self.scene_path, self.drop_invalid), Renderer()
        with renderer:
            result = render_frames(renderer, scene, self.cameras, self.settings, self.target, self.kind,
                                   self.bit_depth, self.resume,
                                   progress=lambda done, total, what: report(done, total),
                                   numbers=self.numbers, record=self.record)
        return Done(result, result.written)


def frame_folder(video: Path) -> Path:
    """The hidden folder beside ``video`` that holds its frames until it is assembled."""
    return video.with_name(f".{video.name}.frames")


def stopped_note(target: FrameTarget, numbers: Sequence[int], sharded: bool,
                 interrupted: bool) -> str | None:
    """What a ``render --path`` stopped by Ctrl-C or SIGTERM (``interrupted``) or an error
    leaves, in a few words for its one line (None: nothing worth saying): a sharded video's
    hidden frames (:func:`stopped_video_note`), after an error too; an interrupted video
    rendered in one process leaves nothing; interrupted frames: how many of the path's are in
    the folder, which ``--resume`` completes (an error, such as a refused ``--resume``, gets
    no such note: it says itself what to do)."""
    if target.is_video and sharded:
        return stopped_video_note(target.video)
    if not interrupted:
        return None
    if target.is_video:
        return (f"no video written ({target.video} is written once every frame is drawn; with "
                "--workers N its frames are kept for --resume)")
    kept = sum(all(p.is_file() for p in target.frame_paths(n)) for n in numbers)
    if not kept:
        return None
    folder = target.frame_path(numbers[0]).parent
    return (f"{kept} of {len(numbers)} frames are in {folder}/; the same command with --resume "
            "renders the rest")


def stopped_video_note(video: Path) -> str | None:
    """What a stopped sharded render of ``video`` (Ctrl-C, SIGTERM) leaves, in one line: the
    complete frames kept in its hidden folder (:func:`frame_folder`) for ``--resume``, or None
    when it holds none, in which case the folder (empty, or holding only temporaries) is
    removed, so nothing is left behind."""
    folder = frame_folder(video)
    if not folder.is_dir():
        return None
    frames = [p for p in folder.iterdir() if p.suffix == ".png" and not p.name.startswith(".")]
    if not frames:
        shutil.rmtree(folder, ignore_errors=True)
        return None
    return (f"{len(frames)} frame{'s' if len(frames) != 1 else ''} kept in the hidden folder "
            f"{folder}/ (no video written): re-run with --resume and workers (--workers N or "
            f"--executor ray) to render the rest and write {video}, or delete the folder")


def render_sharded(scene_path: Path, cameras: Sequence[Camera], settings: RenderSettings,
                   target: FrameTarget, executor: Executor, kind: RendererKind = DEFAULT_RENDERER,
                   bit_depth: int = 8, resume: bool = False, drop_invalid: bool = False,
                   fps: float = 30.0, progress: Optional[ProgressCallback] = None,
                   numbers: Optional[Sequence[int]] = None, lod: Optional[LodSettings] = None,
                   record: Optional[FrameRecord] = None) -> tuple[BatchResult, RunResult]:
    """Render ``cameras`` to ``target`` (images or a video, module doc) on ``executor``:
    local workers get one contiguous chunk each, Ray tasks at most :data:`MAX_CHUNK_FRAMES`.
    Camera i is frame ``numbers[i]`` (default i), as in :func:`splatgl.tasks.batch.render_frames`;
    with ``resume`` the frames there are checked here, before any task starts.  ``lod``: every
    task renders the scene file (a .lod.ply) through that cut.  ``record``: what the frames
    are rendered from, written into each and checked by ``resume``
    (:mod:`splatgl.imagefiles.frame_record`).

    Returns the summed :class:`BatchResult` (``seconds``: wall time including the video's
    encoding) and the run's per-task reports (for :func:`splatgl.tasks.executor.summary`).
    """
    frames = target
    if target.is_video:
        from ..imagefiles.video import _import_av, check_video_size

        # The size check and the install hint before any frame renders (the size first: a
        # wrong size is wrong with PyAV too)
        check_video_size(target.video, cameras[0].width, cameras[0].height)
        _import_av()
        target.prepare()
        frames = FrameTarget.parse(f"{frame_folder(target.video)}/", "png")  # a folder
        bit_depth = 8  # what the video holds; quantised as VideoWriter quantises
    numbers = list(range(len(cameras))) if numbers is None else list(numbers)
    plan = plan_frames(frames, [(c.width, c.height) for c in cameras], numbers, bit_depth, resume,
                       record, cameras)
    frames.prepare()
    n_tasks = (executor.workers if executor.kind is ExecutorKind.LOCAL
               else math.ceil(len(cameras) / MAX_CHUNK_FRAMES))
    tasks = [RenderChunk(Path(scene_path), drop_invalid, tuple(cameras[i] for i in part),
                         tuple(numbers[i] for i in part), settings, frames, RendererKind(kind),
                         bit_depth, resume, lod, record)
             for part in chunks(len(cameras), n_tasks)]
    run = run_tasks(tasks, executor, "frames", progress, RESUME_HINT)
    results = run.values
    seconds = run.seconds
    if target.is_video:
        seconds += assemble_video(frames, numbers, target.video, fps, progress)
        shutil.rmtree(frame_folder(target.video))
    return BatchResult(sum(r.written for r in results), sum(r.skipped for r in results), seconds,
                       sum(r.render_seconds for r in results), plan.damaged, plan.unchecked), run


def assemble_video(frames: FrameTarget, numbers: Sequence[int], video: Path, fps: float,
                   progress: Optional[ProgressCallback] = None) -> float:
    """Encode frame files ``numbers`` of ``frames``, in that order, into ``video`` (atomically:
    the video appears complete or not at all).  Returns the seconds it took."""
    import time

    from ..imagefiles.images import read_image
    from ..imagefiles.video import VideoWriter

    t0 = time.perf_counter()
    first = read_image(frames.frame_path(numbers[0]))
    meter = FrameMeter(len(numbers), progress, unit="frames encoded")
    with VideoWriter(video, first.shape[1], first.shape[0], fps) as writer:
        for k, number in enumerate(numbers):
            writer.write(first if k == 0 else read_image(frames.frame_path(number)))
            meter(k + 1, k + 1)
    return time.perf_counter() - t0
