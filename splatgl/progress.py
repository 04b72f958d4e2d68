"""Progress of long operations (loading, rendering): a callback protocol and a stderr reporter.

The protocol is one callable, ``progress(done, total, what)``:

- ``done`` (int): units finished so far (rows for the PLY reader), non-decreasing,
- ``total`` (int): units in all; the last call has ``done == total``,
- ``what`` (str): a short label such as ``"reading scene.ply"``.

Readers take it as an optional ``progress=None`` argument and call it between chunks; so do
the renderers' long loops (the reference between tile batches, the tile renderer between
bands of its last stage: a renderer object with a ``progress`` attribute calls it there).
Calling it between bounded pieces of work is also what makes Ctrl-C prompt: Python raises
KeyboardInterrupt only between its own statements, never inside one NumPy or OpenGL call.
:func:`default_progress` gives the reporter :func:`splatgl.formats.load_scene` uses when the
caller passes none: a one-line meter on stderr when stderr is a terminal, or whenever the
environment variable ``SPLATGL_PROGRESS`` is ``1`` (``0`` turns it off everywhere).
"""

from __future__ import annotations

import os
import sys
import time
from typing import Callable, Optional, TextIO

#: ``progress(done, total, what)``; see the module docstring.
ProgressCallback = Callable[[int, int, str], None]

#: ``1`` forces the stderr reporter on (even when stderr is not a terminal), ``0`` forces it off.
ENV_VAR = "SPLATGL_PROGRESS"


def enabled(stream: Optional[TextIO] = None) -> bool:
    """Whether to report: ``$SPLATGL_PROGRESS`` if set (``0``/``1``), else is ``stream`` a TTY."""
    env = os.environ.get(ENV_VAR, "").strip().lower()
    if env:
        return env not in ("0", "false", "no", "off")
    stream = sys.stderr if stream is None else stream
    isatty = getattr(stream, "isatty", None)
    try:
        return bool(isatty and isatty())
    except (OSError, ValueError):  # closed or detached stream
        return False


class StderrProgress:
    """A throttled text meter: ``what: 42.0% (420,000 / 1,000,000), about 3 s left``.

    The estimate extrapolates the elapsed time linearly (shown once 2 % is done).

    On a terminal the line is redrawn in place (``\\r``) at most every ``interval`` seconds and
    only once the operation has run for ``delay`` seconds (quick loads print nothing); elsewhere
    (forced by the environment variable) it prints a line at every 25 % and at the end.
    """

    def __init__(self, stream: Optional[TextIO] = None, interval: float = 0.1,
                 delay: float = 0.3, clock: Callable[[], float] = time.monotonic):
        self.stream = sys.stderr if stream is None else stream
        self.interval, self.delay, self.clock = interval, delay, clock
        try:
            self.tty = bool(self.stream.isatty())
        except (AttributeError, OSError, ValueError):
            self.tty = False
        self._start: float | None = None
        self._last = -float("inf")
        self._shown = False
        self._next_step = 0.0

    def __call__(self, done: int, total: int, what: str) -> None:
        now = self.clock()
        if self._start is None or done == 0:
            self._start, self._last, self._shown, self._next_step = now, -float("inf"), False, 0.0
        fraction = done / total if total > 0 else 1.0
        final = done >= total
        text = f"{what}: {100.0 * fraction:5.1f}% ({done:,} / {total:,})"
        elapsed = now - self._start
        if not final and fraction >= 0.02 and elapsed > 0:
            text += f", about {format_seconds(elapsed * (1.0 - fraction) / fraction)} left"
        if self.tty:
            if final and not self._shown:
                return  # finished before the meter was due: print nothing
            if not final and (now - self._start < self.delay or now - self._last < self.interval):
                return
            self.stream.write("\r" + text + ("\n" if final else ""))
        else:
            if not final and fraction < self._next_step:
                return
            self._next_step = min(1.0, (int(fraction * 4) + 1) / 4)
            self.stream.write(text + "\n")
        self._shown, self._last = not final, now
        self.stream.flush()


def format_seconds(seconds: float) -> str:
    """``"4 s"``, ``"2 min 05 s"``, ``"1 h 02 min"``: a duration for a progress line."""
    s = int(round(seconds))
    if s < 60:
        return f"{max(s, 1)} s"
    if s < 3600:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s // 3600} h {s % 3600 // 60:02d} min"


def default_progress() -> Optional[ProgressCallback]:
    """A :class:`StderrProgress` when :func:`enabled`, else None (report nothing)."""
    return StderrProgress() if enabled() else None
