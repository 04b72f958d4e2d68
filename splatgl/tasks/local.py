"""``--workers N``: run tasks (:mod:`splatgl.tasks.task`) in N local processes, each with its
own headless context and its own copy of the scene.

The processes are spawned (a fresh interpreter: no inherited GL state) and take tasks from one
queue in order, so a render's contiguous chunks keep each worker's sort warm and a benchmark's
scenes spread over the workers as they free up.  Workers report progress and results on a
second queue; the parent shows one progress line for all of them.  Ctrl-C / SIGTERM interrupts
every worker (SIGINT), which unwinds like a single process (a frame in hand is finished or
dropped, never half-written); the parent then re-raises.  A worker that dies without reporting
(killed) stops the run with an error naming its task.  A worker's warnings travel to the
parent, which shows them as its own (the command line's one-line policy, splatgl/cli.py).
"""

from __future__ import annotations

import multiprocessing as mp
import os
import pickle
import queue
import signal
import warnings
from typing import Optional, Sequence

from ..errors import SplatglError
from .task import Files, ProgressSum, Task, TaskReport, die_once_for_test, run_here
from ..progress import ProgressCallback

#: Seconds the parent waits on the message queue before checking that the workers live.
POLL_SECONDS = 0.5


def chunks(count: int, workers: int) -> list[range]:
    """``workers`` contiguous, near-equal ranges covering ``range(count)`` (empty ones dropped)."""
    bounds = [round(i * count / workers) for i in range(workers + 1)]
    return [range(a, b) for a, b in zip(bounds, bounds[1:]) if b > a]


def _forward_warnings(messages, current: list) -> None:
    """Send this worker's warnings to the parent (``("warning", task index, (text, category,
    file, line))``) instead of printing them raw on the shared terminal."""
    def show(message, category, filename, lineno, file=None, line=None):
        try:
            pickle.dumps(category)
        except Exception:  # noqa: BLE001 - a class the parent cannot import
            category = RuntimeWarning if issubclass(category, RuntimeWarning) else UserWarning
        messages.put(("warning", current[0], (str(message), category, filename, lineno)))

    warnings.showwarning = show


def reissue_warning(payload) -> None:
    """Show a worker's forwarded warning (:func:`_forward_warnings`) here, as if raised here."""
    text, category, filename, lineno = payload
    warnings.warn_explicit(text, category, filename, lineno)


def _worker(todo, messages) -> None:
    task_index = None
    current = [None]
    _forward_warnings(messages, current)
    try:
        while True:
            item = todo.get()
            if item is None:
                return
            task_index, task = item
            current[0] = task_index
            messages.put(("start", task_index, os.getpid()))
            die_once_for_test(lambda: (messages.close(), messages.join_thread()))
            report = run_here(task, Files(), lambda d, t, i=task_index: messages.put(("progress", i, (d, t))))
            messages.put(("done", task_index, report))
    except SplatglError as exc:
        messages.put(("error", task_index, str(exc)))
    except KeyboardInterrupt:
        messages.put(("interrupted", task_index, None))
    except BaseException as exc:  # noqa: BLE001 - reported to the parent, which raises
        messages.put(("error", task_index, f"worker {os.getpid()} failed: {type(exc).__name__}: {exc}"))


def run_local(tasks: Sequence[Task], workers: int, unit: str = "frames",
              progress: Optional[ProgressCallback] = None, hint: str = "") -> list[TaskReport]:
    """Run ``tasks`` in ``workers`` spawned processes (1: in this process); reports in task
    order.  ``hint`` ends the message of a worker that died (e.g. how to resume)."""
    if workers < 1:
        raise SplatglError(f"--workers must be at least 1, got {workers}")
    meter = ProgressSum(tasks, unit, progress)
    if workers == 1:
        return [run_here(t, Files(), lambda d, n, i=i: meter(i, d, n)) for i, t in enumerate(tasks)]
    ctx = mp.get_context("spawn")
    todo, messages = ctx.Queue(), ctx.Queue()
    for item in enumerate(tasks):
        todo.put(item)
    procs = []
    for _ in range(min(workers, len(tasks))):
        todo.put(None)
        procs.append(ctx.Process(target=_worker, args=(todo, messages), daemon=True))
        procs[-1].start()
    reports: list[Optional[TaskReport]] = [None] * len(tasks)
    running: dict[int, int] = {}  # pid -> task index
    ended = 0  # polls that found every worker gone (one more poll drains their last messages)
    try:
        while any(r is None for r in reports):
            try:
                kind, i, payload = messages.get(timeout=POLL_SECONDS)
            except queue.Empty:
                _check_alive(procs, running, tasks, hint)
                ended = ended + 1 if all(not p.is_alive() for p in procs) else 0
                if ended > 1:
                    raise SplatglError("every worker process ended with tasks left undone") from None
                continue
            if kind == "start":
                running[payload] = i
            elif kind == "progress":
                meter(i, *payload)
            elif kind == "done":
                reports[i] = payload
                running.pop(payload.worker.pid, None)
                meter(i, meter.total[i], meter.total[i])
            elif kind == "warning":
                reissue_warning(payload)
            elif kind == "interrupted":
                raise KeyboardInterrupt
            else:
                raise SplatglError(payload)
    except BaseException:
        for p in procs:
            if p.is_alive() and p.pid is not None:
                os.kill(p.pid, signal.SIGINT)  # unwinds like Ctrl-C: no half-written output
        for p in procs:
            p.join(timeout=30)
        raise
    for p in procs:
        p.join()
    return reports


def _check_alive(procs, running: dict[int, int], tasks: Sequence[Task], hint: str) -> None:
    for p in procs:
        if p.exitcode not in (None, 0):
            what = f" on {tasks[running[p.pid]].label()}" if p.pid in running else ""
            raise SplatglError(f"worker process {p.pid} died{what} (exit code {p.exitcode}) "
                               f"without reporting (killed?){'; ' + hint if hint else ''}") from None
