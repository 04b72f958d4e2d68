"""Atomic writes of small text files (a hidden temporary beside the target, checked, then
renamed), and the one-line message of a failed write."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from ..errors import SplatglError

#: Below this many free bytes a file system counts as full in messages.
FULL_DISK_BYTES = 1 << 16


def disk_note(folder: str | Path) -> str:
    """``"; the disk is full"`` where ``folder``'s file system has (almost) no space left, else
    ``""``: what a short write most often means, said where it is so."""
    try:
        free = shutil.disk_usage(folder).free
    except OSError:
        return ""
    return "; the disk is full" if free < FULL_DISK_BYTES else ""


def write_error(path: str | Path, exc: OSError) -> SplatglError:
    """The one-line error of a failed write of ``path`` (the user's file, never the temporary):
    the system's reason (numpy's short writes give none: "written in part") and the disk note."""
    path = Path(path)
    reason = exc.strerror or "the data was written only in part"
    return SplatglError(f"{path}: cannot write ({reason}){disk_note(path.parent)}")


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` so that readers see the old file or the whole new one; the
    temporary is checked to hold every byte before it is renamed."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.partial{os.getpid()}")
    try:
        tmp.write_bytes(data)
        size = tmp.stat().st_size
        if size != len(data):
            raise SplatglError(f"{path}: cannot write: {size} of {len(data)} bytes written"
                               f"{disk_note(path.parent)}")
        tmp.replace(path)
    except OSError as exc:
        raise write_error(path, exc) from None
    finally:
        if tmp.exists():
            tmp.unlink()


def atomic_write_text(path: str | Path, text: str) -> None:
    """:func:`atomic_write_bytes` of ``text`` in UTF-8."""
    atomic_write_bytes(path, text.encode("utf-8"))
