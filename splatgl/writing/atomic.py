"""The one atomic writer: every file splatgl writes goes to a hidden temporary beside its target
(:func:`temp_path`), is checked, and only then renamed onto the target, so a reader sees the
old file or the whole new one, never a half-written one.

>>> with atomic_target(path, check=image_problem) as tmp:
...     write_pixels(tmp)          # any writer that takes a file name

Leaving the block normally runs ``check(tmp)`` (why the file is not complete, or None) and
renames; leaving it by any exception (a failed write, Ctrl-C, SIGTERM through
:mod:`splatgl.cli`) removes the temporary.  A failed write comes out as one line naming the
target, never the temporary.  :class:`splatgl.writing.outputs.OutputFiles` commits several such
files together; :class:`AtomicTarget` serves writers that span calls (the video writer).
"""

from __future__ import annotations

import errno
import os
import shutil
from pathlib import Path
from typing import Callable

from ..errors import SplatglError

#: Below this many free bytes a file system counts as full in messages.
FULL_DISK_BYTES = 1 << 16

#: Why a written file is not complete (a clause for a message), or None when it is.
Check = Callable[[Path], "str | None"]


def temp_path(target: str | Path) -> Path:
    """The temporary ``target`` is written to: ``.STEM.partialPID.SUFFIX`` beside it (the same
    folder, so the rename is atomic; hidden; the process id, so two processes never share one;
    the same suffix, so writers that pick the format by the name still do)."""
    target = Path(target)
    return target.with_name(f".{target.stem}.partial{os.getpid()}{target.suffix}")


def disk_note(folder: str | Path) -> str:
    """``"; the disk is full"`` where ``folder``'s file system has (almost) no space left, else
    ``""``: what a short write most often means, said where it is so."""
    try:
        usage = shutil.disk_usage(folder)
    except OSError:
        return ""
    # a pseudo file system (/proc, /sys) has no blocks at all: it is not "full"
    return "; the disk is full" if 0 < usage.total and usage.free < FULL_DISK_BYTES else ""


def write_error(path: str | Path, exc: OSError) -> SplatglError:
    """The one-line error of a failed write of ``path`` (the user's file, never the temporary):
    the system's reason (numpy's short writes give none: "written in part") and the disk note."""
    path = Path(path)
    reason = exc.strerror or "the data was written only in part"
    # the disk is named only where the error could mean it (no room, or a short write)
    full = exc.errno is None or exc.errno in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)
    return SplatglError(f"{path}: cannot write ({reason}){disk_note(path.parent) if full else ''}")


def cannot_write(path: str | Path, problem: str) -> SplatglError:
    """The one-line error of a write that finished but left ``path`` incomplete (``problem``:
    what a check found)."""
    path = Path(path)
    return SplatglError(f"{path}: cannot write: {problem}{disk_note(path.parent)}")


def size_problem(path: Path, expected: int) -> str | None:
    """Why ``path`` does not hold ``expected`` bytes (None when it does)."""
    size = path.stat().st_size
    return None if size == expected else f"{size} of {expected} bytes written"


def naming_targets(exc: BaseException, targets: dict[Path, Path]) -> BaseException:
    """``exc`` naming the targets where it named their temporaries (``targets``: temporary ->
    target): an ``OSError`` on a temporary becomes the one-line :func:`write_error` of its
    target; a :class:`SplatglError`'s text is rewritten in place (its class kept); any other
    exception is returned as it is."""
    if isinstance(exc, OSError):
        for tmp, target in targets.items():
            if exc.filename in (str(tmp), tmp):
                return write_error(target, exc)
        return exc
    if isinstance(exc, SplatglError):
        text = str(exc)
        for tmp, target in targets.items():
            text = text.replace(str(tmp), str(target)).replace(tmp.name, target.name)
            if getattr(exc, "path", None) == str(tmp):  # SceneFormatError's file
                exc.path = str(target)
        if text != str(exc):
            exc.args = (text,)
    return exc


class AtomicTarget:
    """One file written to :attr:`tmp` and published onto :attr:`path` by :meth:`commit`.

    As a context manager it yields the temporary and commits on a normal exit; on any
    exception it removes the temporary, and a failed write (any ``OSError``, or a
    :class:`SplatglError` naming the temporary) is re-raised as one line naming ``path``.
    """

    def __init__(self, path: str | Path, check: Check | None = None):
        self.path = Path(path)
        #: The file replaced: :attr:`path`, or where it leads when it is a symbolic link (a
        #: link is written through, never replaced by a plain file).
        self.dest = Path(os.path.realpath(self.path)) if self.path.is_symlink() else self.path
        self.tmp = temp_path(self.dest)
        self.check = check

    def verify(self) -> None:
        """Raise :func:`cannot_write` when :attr:`check` finds the temporary incomplete."""
        problem = self.check(self.tmp) if self.check is not None else None
        if problem is not None:
            raise cannot_write(self.path, problem)

    def publish(self) -> None:
        """Rename the temporary onto the target (a link's target, :attr:`dest`)."""
        try:
            os.replace(self.tmp, self.dest)
        except OSError as exc:
            raise write_error(self.path, exc) from None

    def commit(self) -> None:
        """:meth:`verify`, then :meth:`publish`; the temporary is gone either way."""
        try:
            self.verify()
            self.publish()
        except OSError as exc:  # the check could not read the temporary back
            raise write_error(self.path, exc) from None
        except SplatglError as exc:  # a check's words about the temporary
            naming_targets(exc, {self.tmp: self.path})
            raise
        finally:
            self.discard()

    def discard(self) -> None:
        """Remove the temporary, if there is one."""
        self.tmp.unlink(missing_ok=True)

    def __enter__(self) -> Path:
        return self.tmp

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.commit()
            return
        self.discard()
        if isinstance(exc, OSError):
            raise write_error(self.path, exc) from None
        naming_targets(exc, {self.tmp: self.path})  # a SplatglError: rewritten in place


def atomic_target(path: str | Path, check: Check | None = None) -> AtomicTarget:
    """``with atomic_target(path, check) as tmp:`` write ``tmp``; see :class:`AtomicTarget`."""
    return AtomicTarget(path, check)


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically; the temporary must hold every byte."""
    with atomic_target(path, lambda tmp: size_problem(tmp, len(data))) as tmp:
        tmp.write_bytes(data)


def atomic_write_text(path: str | Path, text: str) -> None:
    """:func:`atomic_write_bytes` of ``text`` in UTF-8."""
    atomic_write_bytes(path, text.encode("utf-8"))
