"""One way to run a list of independent tasks in this process, in N local worker processes
(``--workers N``) or as Ray tasks (``--executor ray``), used by ``render --path``, ``eval`` and
``bench``.

A task (:class:`Task`) is a picklable description of one piece of work (a chunk of a camera
path, a chunk of a dataset's views, one scene of a benchmark) that loads what it needs itself
(the scene file through :class:`Files`, so Ray can ship it through its object store), runs, and
returns a :class:`Done`: its value and how many units (frames, views, rows) it did.  The runners
(:func:`splatgl.tasks.local.run_local`, :func:`splatgl.tasks.ray.run_ray`) return one
:class:`TaskReport` per task, in task order, with the worker that ran it; :func:`summary` turns
them into the per-worker rates printed at the end.
"""

from __future__ import annotations

import argparse
import contextlib
import enum
import os
import socket
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator, Optional, Protocol, Sequence

from ..errors import SplatglError
from ..progress import ProgressCallback

#: ``report(done, total)``: units of one task finished so far (the runner adds the tasks up).
TaskProgress = Callable[[int, int], None]
#: Test hook: a file path; the first worker process (local or Ray) to start a task while the
#: file is missing creates it and dies, as a killed or preempted worker would.
KILL_ONCE_ENV = "SPLATGL_TEST_KILL_ONCE"


class ExecutorKind(enum.Enum):
    LOCAL = "local"
    RAY = "ray"


@dataclass(frozen=True)
class Executor:
    """Where tasks run: ``workers`` local processes (1: this process), or Ray (``ray_address``
    None starts a local Ray; ``ray_gpus`` GPUs reserved per task)."""

    kind: ExecutorKind = ExecutorKind.LOCAL
    workers: int = 1
    ray_address: str | None = None
    ray_gpus: float = 0.0

    @property
    def sharded(self) -> bool:
        """True when the work leaves this process."""
        return self.kind is ExecutorKind.RAY or self.workers > 1


@dataclass(frozen=True)
class Done:
    """What a task returns: its ``value`` and the ``count`` of units it did (frames rendered,
    views scored, benchmark rows), for the summary."""

    value: Any
    count: int


@dataclass(frozen=True)
class WorkerId:
    """The process that ran a task: host name, IP (Ray only) and process id."""

    host: str
    pid: int
    ip: str | None = None

    @classmethod
    def here(cls, ip: str | None = None) -> "WorkerId":
        return cls(socket.gethostname(), os.getpid(), ip)

    def __str__(self) -> str:
        where = f"{self.host} {self.ip}" if self.ip and self.ip != self.host else self.host
        return f"{where}, pid {self.pid}"


@dataclass(frozen=True)
class TaskReport:
    """One finished task: its result, the worker and the seconds the task took there."""

    done: Done
    worker: WorkerId
    seconds: float


class Files:
    """How a task reaches its input files: on this machine, the paths themselves.  The Ray
    runner passes a subclass that writes the bytes it shipped to a temporary folder."""

    @contextlib.contextmanager
    def local(self, path: Path) -> Iterator[Path]:
        """A readable local path holding the contents of ``path`` while the block runs."""
        yield Path(path)

    def load_scene(self, path: Path, drop_invalid: bool = False):
        """The scene file ``path`` loaded quietly through :meth:`local` (every task's input)."""
        from ..formats import load_scene

        with self.local(path) as local:
            return load_scene(local, drop_invalid=drop_invalid, progress=lambda *a: None)


class Task(Protocol):
    """A picklable piece of work (module doc)."""

    #: Progress units (frames, views, steps) this task is expected to do.
    units: int

    def inputs(self) -> tuple[Path, ...]:
        """Files the task reads through :class:`Files` (Ray ships them to the workers)."""

    def label(self) -> str:
        """A few words naming the task in errors, e.g. ``frames 32-63``."""

    def run(self, files: Files, report: TaskProgress) -> Done:
        """Do the work; call ``report(done, total)`` as units finish."""


def die_once_for_test(flush: Callable[[], None] | None = None) -> None:
    """The :data:`KILL_ONCE_ENV` hook; only worker processes call it (``flush``: send what the
    worker has queued for the parent first)."""
    marker = os.environ.get(KILL_ONCE_ENV)
    if marker and not Path(marker).exists():
        Path(marker).write_text("killed once\n")
        if flush is not None:
            flush()
        os._exit(1)


def run_here(task: Task, files: Files, report: TaskProgress, ip: str | None = None) -> TaskReport:
    """Run ``task`` in this process and time it (what every runner does in its workers)."""
    t0 = time.perf_counter()
    done = task.run(files, report)
    return TaskReport(done, WorkerId.here(ip), time.perf_counter() - t0)


@dataclass(frozen=True)
class RunResult:
    """Every task's report, in task order, and the wall time of the whole run."""

    reports: tuple[TaskReport, ...]
    seconds: float

    @property
    def values(self) -> list[Any]:
        return [r.done.value for r in self.reports]


def run_tasks(tasks: Sequence[Task], executor: Executor, unit: str = "frames",
              progress: Optional[ProgressCallback] = None, hint: str = "") -> RunResult:
    """Run ``tasks`` where ``executor`` says; one progress line over all of them in ``unit``.
    ``hint`` ends the error of a task that failed for good (e.g. how to resume)."""
    t0 = time.perf_counter()
    if executor.kind is ExecutorKind.RAY:
        from .ray import run_ray

        reports = run_ray(tasks, executor.ray_address, executor.ray_gpus, unit, progress, hint)
    else:
        from .local import run_local

        reports = run_local(tasks, executor.workers, unit, progress, hint)
    return RunResult(tuple(reports), time.perf_counter() - t0)


def summary(run: RunResult, unit: str = "frames") -> str:
    """Per worker: units, busy seconds and rate; then the total over the wall time, e.g.
    ``worker 0 (host, pid 12): 16 frames in 3.5 s, 4.57 frames/s`` ...
    ``total: 32 frames in 7.1 s, 4.51 frames/s (2 workers, 2 tasks)``."""
    workers: dict[WorkerId, list[TaskReport]] = {}
    for r in run.reports:
        workers.setdefault(r.worker, []).append(r)
    lines = []
    for n, (worker, reports) in enumerate(workers.items()):
        count = sum(r.done.count for r in reports)
        busy = sum(r.seconds for r in reports)
        tasks = f", {_count(len(reports), 'task')}" if len(reports) > 1 else ""
        lines.append(f"worker {n} ({worker}): {count} {unit} in {busy:.1f} s, "
                     f"{_rate(count, busy)} {unit}/s{tasks}")
    total = sum(r.done.count for r in run.reports)
    lines.append(f"total: {total} {unit} in {run.seconds:.1f} s, {_rate(total, run.seconds)} {unit}/s "
                 f"({_count(len(workers), 'worker')}, {_count(len(run.reports), 'task')})")
    return "\n".join(lines)


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}{'' if n == 1 else 's'}"


def _rate(count: int, seconds: float) -> str:
    return f"{count / seconds:.2f}" if seconds > 0 else "-"


def add_executor_arguments(p: argparse.ArgumentParser, what: str, ray_chunk: str) -> argparse._ArgumentGroup:
    """``--workers``, ``--executor``, ``--ray-address``, ``--ray-gpus`` (one wording for every
    command; ``what`` says what is split, ``ray_chunk`` what one Ray task does)."""
    g = p.add_argument_group("running on more processes or machines")
    g.add_argument("--workers", type=int, default=1, metavar="N",
                   help=f"run in N local processes, each with its own context and copy of the "
                        f"scene, on {what} (default 1: this process)")
    g.add_argument("--executor", choices=[k.value for k in ExecutorKind], default="local",
                   help=f"'local' (this process, or --workers processes) or 'ray' ({ray_chunk}, on "
                        "a local Ray or the cluster at --ray-address; install with "
                        "pip install 'splatgl[ray]')")
    g.add_argument("--ray-address", default=None, metavar="ADDRESS",
                   help="with --executor ray: the cluster to join ('auto' for the one this node "
                        "belongs to; default: start a local Ray)")
    g.add_argument("--ray-gpus", type=float, default=0.0, metavar="N",
                   help="with --executor ray: GPUs each task reserves (default 0, so CPU-only "
                        "clusters work)")
    return g


def executor_from_args(args: argparse.Namespace) -> Executor:
    """The :class:`Executor` the options name; checks them (and that Ray is importable)."""
    if args.workers < 1:
        raise SplatglError(f"--workers must be at least 1, got {args.workers}")
    kind = ExecutorKind(args.executor)
    if kind is ExecutorKind.RAY and args.workers != 1:
        raise SplatglError("--workers is for --executor local; Ray decides where its tasks run")
    if not args.ray_gpus >= 0:
        raise SplatglError(f"--ray-gpus must be 0 or more, got {args.ray_gpus}")
    if kind is not ExecutorKind.RAY and (args.ray_address is not None or args.ray_gpus):
        raise SplatglError("--ray-address and --ray-gpus need --executor ray")
    if kind is ExecutorKind.RAY:
        from .ray import import_ray
        import_ray()  # the install hint before any work
    return Executor(kind, args.workers, args.ray_address, args.ray_gpus)


class ProgressSum:
    """One progress line over many tasks: each task's latest ``(done, total)`` added up (a
    task's total starts as its :attr:`Task.units` and may be corrected by its reports)."""

    def __init__(self, tasks: Sequence[Task], unit: str, progress: Optional[ProgressCallback]):
        from .batch import FrameMeter

        self.done = [0] * len(tasks)
        self.total = [t.units for t in tasks]
        self.meter = FrameMeter(sum(self.total), progress, unit=unit)

    def __call__(self, task: int, done: int, total: int) -> None:
        if (self.done[task], self.total[task]) == (done, total):
            return  # nothing new (a task's end after its last frame): no repeated line
        self.done[task], self.total[task] = done, total
        self.meter.total = sum(self.total)
        n = sum(self.done)
        self.meter(n, n)
