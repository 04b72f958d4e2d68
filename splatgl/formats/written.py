"""Checks of a scene file just written, before it is renamed into place: the file must hold
what its own header says it holds, so a write cut short (a full disk) is never published.

Cheap by design (headers, sizes and trailers; the SPZ gzip stream is inflated, which costs a
fraction of encoding it): a binary PLY's size must equal its header's element sizes, a GLB's
its length field, a zip (SOG) must end with its central directory, a gzip stream (SPZ) must
reach its end.  Formats without such structure are checked for being non-empty.
"""

from __future__ import annotations

import os
import struct
import zipfile
import zlib
from pathlib import Path
from typing import Callable, TypeVar

from ..output.atomic import disk_note, write_error
from ..errors import SplatglError

T = TypeVar("T")

#: Bytes read at a time when inflating a gzip stream to its end.
_CHUNK = 1 << 20


def write_checked(path: str | Path, write: Callable[[Path], T]) -> T:
    """``write(tmp)`` to a temporary beside ``path``, checked (:func:`written_problem`), then
    renamed onto ``path``; returns what ``write`` returns.  A failed or short write raises one
    line naming ``path`` (never the temporary) and leaves nothing behind."""
    path = Path(path)
    tmp = path.with_name(path.name + ".partial")
    try:
        value = write(tmp)
        problem = written_problem(tmp)
        if problem is not None:
            raise SplatglError(f"{path}: cannot write: {problem}{disk_note(path.parent)}")
        tmp.replace(path)
        return value
    except OSError as exc:
        raise write_error(path, exc) from None
    finally:
        if tmp.exists():
            tmp.unlink()


def write_together(files: dict[Path, bytes], write_last: Callable[[], None]) -> None:
    """Several files of one output, all or none: each of ``files`` (path -> bytes) to a
    temporary beside it, checked to hold all its bytes, then ``write_last()`` (the file that
    names them, such as SOG's meta.json, to the caller's own temporary); only then are they
    renamed into place.  Any failure removes every temporary and leaves the folder as it was."""
    temps = {path: path.with_name(f".{path.name}.partial{os.getpid()}") for path in files}
    try:
        for path, data in files.items():
            temps[path].write_bytes(data)
            size = temps[path].stat().st_size
            if size != len(data):
                raise SplatglError(f"{path}: cannot write: {size} of {len(data)} bytes written"
                                   f"{disk_note(path.parent)}")
        write_last()
        for path, tmp in list(temps.items()):
            os.replace(tmp, path)
            del temps[path]
    finally:
        for tmp in temps.values():
            tmp.unlink(missing_ok=True)


def written_problem(path: str | Path) -> str | None:
    """Why the file at ``path`` is not complete (one clause for a message), or None."""
    path = Path(path)
    size = path.stat().st_size
    if size == 0:
        return "the file is empty"
    with open(path, "rb") as fh:
        head = fh.read(16)
        if head.startswith(b"ply"):
            return _ply_problem(path, size)
        if head.startswith(b"glTF"):
            total = struct.unpack_from("<I", head, 8)[0] if len(head) >= 12 else -1
            return None if total == size else f"the file is cut short ({size} of {total} bytes)"
        if head.startswith(b"PK"):
            return None if zipfile.is_zipfile(path) else f"the file is cut short ({size} bytes, no zip directory)"
        if head.startswith(b"\x1f\x8b"):
            fh.seek(0)
            return _gzip_problem(fh, size)
    return None


def _ply_problem(path: Path, size: int) -> str | None:
    from . import ply

    with open(path, "rb") as fh:
        try:
            header = ply.parse_header(path, fh)
        except SplatglError:
            return f"the file is cut short ({size} bytes, inside the PLY header)"
    if header.order is None or any(e.has_list for e in header.elements):
        return None  # ASCII or list properties: no size to expect
    expected = header.body_offset + sum(e.count * e.dtype(header.order).itemsize for e in header.elements)
    return None if expected == size else f"the file is cut short ({size} of {expected} bytes)"


def _gzip_problem(fh, size: int) -> str | None:
    inflate = zlib.decompressobj(wbits=31)
    try:
        while not inflate.eof:
            chunk = fh.read(_CHUNK)
            if not chunk:
                break
            inflate.decompress(chunk, 0)
    except zlib.error as exc:
        return f"the gzip stream is damaged ({exc})"
    return None if inflate.eof else f"the file is cut short ({size} bytes, the gzip stream does not end)"
