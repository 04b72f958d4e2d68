"""Exceptions splatgl raises for bad input.  The CLI turns them into one line and exit code 2."""

from __future__ import annotations


class SplatglError(Exception):
    """Base class of every user-facing error (bad files, bad arguments, no OpenGL)."""


class SceneFormatError(SplatglError, ValueError):
    """A scene file is malformed or holds invalid values.

    The message always names the file and, where one is at fault, the field; for bad values it
    says how many rows are affected and the first index.
    """

    def __init__(self, path: object, message: str, field: str | None = None):
        self.path = str(path)
        self.field = field
        where = f"{self.path}: " if path is not None else ""
        what = f"field '{field}': " if field else ""
        super().__init__(f"{where}{what}{message}")


class CameraError(SplatglError, ValueError):
    """A camera file or camera parameters are invalid."""


class ContextError(SplatglError, RuntimeError):
    """No OpenGL context could be created; the message lists every backend tried."""


class ShaderError(SplatglError, RuntimeError):
    """A shader failed to preprocess or compile; the message names file and line."""


def add_note(exc: BaseException, note: str) -> BaseException:
    """Attach ``note`` (what a stopped or failed command leaves, how to go on) to ``exc``, which
    the CLI then prints on its one line after the error or ``interrupted``; returns ``exc``."""
    before = note_of(exc)
    exc.splatgl_note = note if before is None else f"{before}; {note}"
    return exc


def note_of(exc: BaseException) -> str | None:
    """The note :func:`add_note` attached to ``exc``, if any."""
    return getattr(exc, "splatgl_note", None)


def require(value, kind, caller: str, what: str, need: str, reads: tuple[str, ...] = ()):
    """``value`` if it is a ``kind`` (a type or tuple of types; or, where ``reads`` is given,
    has those attributes); else a TypeError in one line: ``caller``, the argument ``what``,
    what it must be (``need``, with how to make one) and what it was given.  The public
    functions check their arguments with it before any work."""
    if isinstance(value, kind) or reads and all(hasattr(value, a) for a in reads):
        return value
    shown, name = " ".join(repr(value).split()), type(value).__name__
    shown = shown if len(shown) <= 60 else shown[:57] + "..."
    got = shown if value is None or shown.startswith(name) else f"{name} {shown}"
    raise TypeError(f"{caller}: {what} must be {need}, got {got}")
