"""``--executor ray``: tasks (:mod:`splatgl.tasks.task`) as Ray tasks, one Ray task each.

Each Ray task runs one splatgl task exactly as a ``--workers`` process does (its own scene
load and headless context), so the output equals a single-process run's.  The files a task
reads (:meth:`Task.inputs`: the scene) reach the workers through Ray's object store (each
file's bytes put once), so workers on other machines need no copy of them; what a task writes
(frames) and other files it reads (a dataset's photographs) must be on a file system every
worker shares (a shared file system on a cluster, the local disk on one machine).

Failures: Ray re-runs a task whose worker died (``max_retries``); a task that raised is retried
as well (``retry_exceptions``), so a crashed or killed worker costs its chunk again, never a
missing or half-written frame (frames are written atomically).  A run that still fails names the
task; for renders ``--resume`` then renders only the missing frames.  Ctrl-C cancels every task.

Install with ``pip install 'splatgl[ray]'``.
"""

from __future__ import annotations

import contextlib
import tempfile
from pathlib import Path
from typing import Iterator, Optional, Sequence

from ..errors import SplatglError
from .task import Files, ProgressSum, Task, TaskReport, die_once_for_test, run_here
from ..progress import ProgressCallback

#: How to get Ray, for the one-line error where it is missing.
INSTALL_HINT = "--executor ray needs Ray: pip install 'splatgl[ray]'"
#: Frames (or views) per task, at most: small enough for a progress line that moves and for
#: cheap retries, large enough that each task's scene load and shader compile are amortised.
MAX_CHUNK_FRAMES = 32
#: Retries of a task whose worker died or that raised.
MAX_RETRIES = 3


def import_ray():
    """The ``ray`` module, or :class:`SplatglError` with the install hint."""
    try:
        import ray
    except ImportError:
        raise SplatglError(INSTALL_HINT) from None
    return ray


class ShippedFiles(Files):
    """Input files whose bytes came through Ray's object store: written to a temporary folder
    under their own names (the loaders look at the suffixes) for the block that reads them."""

    def __init__(self, refs: dict[str, object]):
        self.refs = refs

    @contextlib.contextmanager
    def local(self, path: Path) -> Iterator[Path]:
        ray = import_ray()
        with tempfile.TemporaryDirectory(prefix="splatgl-ray-") as tmp:
            copy = Path(tmp) / Path(path).name
            copy.write_bytes(ray.get(self.refs[str(path)]))
            yield copy


def run_task(task: Task, refs: dict[str, object]) -> TaskReport:
    """Body of a Ray task: run ``task`` with its input files from the object store."""
    die_once_for_test()  # tests: the worker dies mid-run, as a preempted or crashed node would
    import ray

    return run_here(task, ShippedFiles(refs), lambda done, total: None, ray.util.get_node_ip_address())


def connect(address: str | None):
    """The ``ray`` module, initialised (``address`` None: a local Ray on this machine)."""
    ray = import_ray()
    if not ray.is_initialized():
        try:
            ray.init(address=address, include_dashboard=False, log_to_driver=False,
                     logging_level="ERROR")
        except (ConnectionError, RuntimeError, ValueError) as exc:
            raise SplatglError(f"--ray-address {address}: cannot connect to Ray ({exc})") from None
    return ray


def check_gpus(ray, num_gpus: float) -> None:
    """Refuse ``--ray-gpus N`` where no live node of the cluster has N GPUs: Ray would queue
    every task forever, silently (a machine without a GPU, a CPU-only cluster)."""
    if not num_gpus > 0:
        return
    nodes = [n for n in ray.nodes() if n.get("Alive")]
    most = max((float(n.get("Resources", {}).get("GPU", 0.0)) for n in nodes), default=0.0)
    if most < num_gpus:
        raise SplatglError(f"--ray-gpus {num_gpus:g}: no node of the Ray cluster has {num_gpus:g} "
                           f"GPU{'s' if num_gpus != 1 else ''} (at most {most:g} on one of its "
                           f"{len(nodes)} node{'s' if len(nodes) != 1 else ''}), so no task "
                           "could ever start; use --ray-gpus 0 (the default) or a cluster with GPUs")


def run_ray(tasks: Sequence[Task], address: str | None = None, num_gpus: float = 0.0,
            unit: str = "frames", progress: Optional[ProgressCallback] = None,
            hint: str = "") -> list[TaskReport]:
    """Run ``tasks`` as Ray tasks (module doc); reports in task order.

    ``address``: a running cluster (``ray start --head`` prints it; ``"auto"`` finds the local
    one); None starts a local Ray on this machine.  ``num_gpus``: GPUs each task reserves
    (0: CPU-only clusters and this machine work).  Progress moves as tasks finish.
    """
    if not num_gpus >= 0:
        raise SplatglError(f"--ray-gpus must be 0 or more, got {num_gpus}")
    ray = connect(address)
    check_gpus(ray, num_gpus)
    remote = ray.remote(num_gpus=num_gpus, max_retries=MAX_RETRIES, retry_exceptions=True)(run_task)
    shipped: dict[str, object] = {}
    for task in tasks:
        for path in task.inputs():
            if str(path) not in shipped:
                try:
                    shipped[str(path)] = ray.put(Path(path).read_bytes())
                except OSError as exc:
                    raise SplatglError(f"{path}: cannot read ({exc.strerror})") from None
    meter = ProgressSum(tasks, unit, progress)
    index = {}
    for i, task in enumerate(tasks):
        refs = {str(p): shipped[str(p)] for p in task.inputs()}
        index[remote.remote(task, refs)] = i
    pending = list(index)
    reports: list[Optional[TaskReport]] = [None] * len(tasks)
    try:
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            i = index[ready[0]]
            try:
                reports[i] = ray.get(ready[0])
            except ray.exceptions.RayError as exc:
                raise SplatglError(
                    f"{tasks[i].label()} failed after {MAX_RETRIES} retries "
                    f"({type(exc).__name__}: {str(exc).strip().splitlines()[-1][:200]})"
                    f"{'; ' + hint if hint else ''}") from None
            meter(i, meter.total[i], meter.total[i])
    except BaseException:
        for ref in pending:
            ray.cancel(ref, force=True)
        raise
    return reports
