"""Run a list of independent tasks (:mod:`splatgl.tasks.task`) in this process, in N local
worker processes (``--workers N``, :mod:`splatgl.tasks.local`) or as Ray tasks (``--executor
ray``, :mod:`splatgl.tasks.ray`), used by ``render --path``, ``eval`` and ``bench``.

:func:`run_tasks` returns one :class:`~splatgl.tasks.task.TaskReport` per task, in task order,
with the worker that ran it; :func:`summary` turns them into the per-worker rates printed at the
end.  The command-line options that make an :class:`Executor` are in
:mod:`splatgl.commands._executor`.
"""

from __future__ import annotations

import enum
import time
from dataclasses import dataclass
from typing import Any, Optional, Sequence

from ..progress import ProgressCallback
from .task import Task, TaskReport, WorkerId


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
