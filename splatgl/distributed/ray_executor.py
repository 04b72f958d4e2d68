"""``--executor ray``: a camera path's frames as Ray tasks, one task per contiguous chunk.

Each task loads the scene, opens its own headless context and runs
:func:`splatgl.batch.render_frames` on its chunk, writing frames under their global numbers,
exactly as a ``--workers`` process does, so the files equal a single-process render's frame by
frame.  The scene reaches the tasks through Ray's object store (the file's bytes, put once),
so workers on other machines need no copy of it; the output folder must be one every worker
can write (a shared file system on a cluster, the local disk on one machine).

Failures: Ray re-runs a task whose worker died (``max_retries``); a task that raised is retried
as well (``retry_exceptions``), so a crashed or killed worker costs its chunk's frames again,
never a missing or half-written frame (frames are written atomically).  A run that still fails
names the chunk; ``--resume`` then renders only the missing frames.  Ctrl-C cancels every task.

Install with ``pip install 'splatgl[ray]'``.
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path
from typing import Optional, Sequence

from ..batch import BatchResult, FrameMeter
from ..camera import Camera
from ..errors import SplatglError
from ..frame_output import FrameTarget
from ..progress import ProgressCallback
from ..settings import RenderSettings, RendererKind
from ..workers import ChunkJob, chunks

#: How to get Ray, for the one-line error where it is missing.
INSTALL_HINT = "--executor ray needs Ray: pip install 'splatgl[ray]'"
#: Frames per task, at most: small enough for a progress line that moves and for cheap retries,
#: large enough that each task's scene load and shader compile are amortised.
MAX_CHUNK_FRAMES = 32
#: Retries of a task whose worker died or that raised.
MAX_RETRIES = 3
#: Test hook: a file path; the first task to find it missing creates it and kills its worker,
#: so tests can check that a killed worker's chunk is retried.
KILL_ONCE_ENV = "SPLATGL_TEST_RAY_KILL_ONCE"


def import_ray():
    """The ``ray`` module, or :class:`SplatglError` with the install hint."""
    try:
        import ray
    except ImportError:
        raise SplatglError(INSTALL_HINT) from None
    return ray


def render_chunk(scene_bytes: bytes, job: ChunkJob) -> tuple[int, int, float, float]:
    """Body of a Ray task: (written, skipped, seconds, render_seconds) of one chunk."""
    from ..batch import render_frames
    from ..formats import load_scene
    from ..render import Renderer

    marker = os.environ.get(KILL_ONCE_ENV)
    if marker and not Path(marker).exists():
        Path(marker).write_text("killed once\n")
        os._exit(1)  # the worker dies mid-run, as a preempted or crashed node would
    with tempfile.TemporaryDirectory(prefix="splatgl-ray-") as tmp:
        path = Path(tmp) / f"scene{job.scene_path.suffix}"   # the bytes came through Ray
        path.write_bytes(scene_bytes)
        scene = load_scene(path, drop_invalid=job.drop_invalid)
    with Renderer() as renderer:
        r = render_frames(renderer, scene, job.cameras, job.settings, job.target, job.kind,
                          job.bit_depth, job.resume, first_frame=job.first_frame)
    return r.written, r.skipped, r.seconds, r.render_seconds


def render_frames_ray(scene_path: Path, cameras: Sequence[Camera], settings: RenderSettings,
                      target: FrameTarget, kind: RendererKind = RendererKind.QUAD,
                      bit_depth: int = 8, resume: bool = False, drop_invalid: bool = False,
                      progress: Optional[ProgressCallback] = None, address: str | None = None,
                      num_gpus: float = 0.0, tasks: int | None = None) -> BatchResult:
    """Render ``cameras`` to image ``target`` as Ray tasks (module doc).

    ``address``: a running cluster (``ray start --head`` prints it; ``"auto"`` finds the local
    one); None starts a local Ray on this machine.  ``num_gpus``: GPUs each task reserves
    (0: CPU-only clusters and this machine work).  ``tasks``: how many chunks (default: enough
    for chunks of at most :data:`MAX_CHUNK_FRAMES`).  Returns the summed :class:`BatchResult`,
    ``seconds`` being the wall time of the whole run.
    """
    if target.is_video:
        raise SplatglError("--executor ray renders image frames; write a video with one process")
    if not num_gpus >= 0:
        raise SplatglError(f"--ray-gpus must be 0 or more, got {num_gpus}")
    ray = import_ray()
    target.prepare()
    if not ray.is_initialized():
        try:
            ray.init(address=address, include_dashboard=False, log_to_driver=False,
                     logging_level="ERROR")
        except (ConnectionError, RuntimeError, ValueError) as exc:
            raise SplatglError(f"--ray-address {address}: cannot connect to Ray ({exc})") from None
    remote = ray.remote(num_gpus=num_gpus, max_retries=MAX_RETRIES,
                        retry_exceptions=True)(render_chunk)
    scene_ref = ray.put(Path(scene_path).read_bytes())
    n_tasks = tasks or max(1, -(-len(cameras) // MAX_CHUNK_FRAMES))
    pending, sizes = [], {}
    t0 = time.perf_counter()
    for part in chunks(len(cameras), n_tasks):
        job = ChunkJob(Path(scene_path), drop_invalid, tuple(cameras[i] for i in part),
                       part.start, settings, target, RendererKind(kind), bit_depth, resume)
        ref = remote.remote(scene_ref, job)
        pending.append(ref)
        sizes[ref] = part
    meter = FrameMeter(len(cameras), progress)
    totals = [0, 0, 0.0, 0.0]
    done = 0
    try:
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            part = sizes[ready[0]]
            try:
                result = ray.get(ready[0])
            except ray.exceptions.RayError as exc:
                raise SplatglError(
                    f"frames {part.start}-{part.stop - 1} failed after {MAX_RETRIES} retries "
                    f"({type(exc).__name__}: {str(exc).strip().splitlines()[-1][:200]}); "
                    "re-run with --resume to render the missing frames") from None
            for i, v in enumerate(result):
                totals[i] += v
            done += len(part)
            meter(done, done)
    except BaseException:
        for ref in pending:
            ray.cancel(ref, force=True)
        raise
    return BatchResult(int(totals[0]), int(totals[1]), time.perf_counter() - t0, totals[3])
