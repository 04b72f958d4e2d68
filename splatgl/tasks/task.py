"""What a task is, for every runner: a picklable piece of work (:class:`Task`), how it reaches
its input files (:class:`Files`), what it returns (:class:`Done`) and what a runner reports of it
(:class:`TaskReport`, timed by :func:`run_here` in the worker), plus the runners' shared
progress line (:class:`ProgressSum`) and test hook (:func:`die_once_for_test`).

A task (:class:`Task`) is a picklable description of one piece of work (a chunk of a camera
path, a chunk of a dataset's views, one scene of a benchmark) that loads what it needs itself
(the scene file through :class:`Files`, so Ray can ship it through its object store), runs, and
returns a :class:`Done`: its value and how many units (frames, views, rows) it did.  The runners
(:func:`splatgl.tasks.local.run_local`, :func:`splatgl.tasks.ray.run_ray`) build on this module
only; :func:`splatgl.tasks.executor.run_tasks`, above them, picks one.
"""

from __future__ import annotations

import contextlib
import os
import socket
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator, Optional, Protocol, Sequence

from ..progress import ProgressCallback

#: ``report(done, total)``: units of one task finished so far (the runner adds the tasks up).
TaskProgress = Callable[[int, int], None]
#: Test hook: a file path; the first worker process (local or Ray) to start a task while the
#: file is missing creates it and dies, as a killed or preempted worker would.
KILL_ONCE_ENV = "SPLATGL_TEST_KILL_ONCE"


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
