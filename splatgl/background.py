"""One piece of work on a background thread, its result collected later.

Used for one-off preparations that a later frame will need (the LOD leaves' chunked cull, the
compiled cull kernel): they overlap the frames drawn meanwhile (NumPy and LLVM release the GIL
for most of their work).  The thread is a daemon, so it never holds up Ctrl-C or the process's
exit; nothing it makes is written anywhere, so abandoning it leaves nothing behind.
"""

from __future__ import annotations

import threading


class Background:
    """``fn(*args)`` started on a daemon thread; :meth:`result` waits for it and returns its
    value or re-raises its exception; :meth:`done` tells without waiting."""

    def __init__(self, fn, *args, name: str = "splatgl-background"):
        self._value = self._error = None
        self._thread = threading.Thread(target=self._run, args=(fn, args), daemon=True, name=name)
        self._thread.start()

    def _run(self, fn, args) -> None:
        try:
            self._value = fn(*args)
        except BaseException as exc:  # handed to the caller of result()
            self._error = exc

    def done(self) -> bool:
        return not self._thread.is_alive()

    def result(self):
        self._thread.join()
        if self._error is not None:
            raise self._error
        return self._value
