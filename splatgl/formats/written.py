"""Checks of a scene file just written, before it is renamed into place: the file must hold
what its own header says it holds, so a write cut short (a full disk) is never published.

Cheap by design (headers, sizes and trailers; the SPZ gzip stream is inflated, which costs a
fraction of encoding it): a binary PLY's size must equal its header's element sizes, a GLB's
its length field, a zip (SOG) must end with its central directory, a gzip stream (SPZ) must
reach its end.  Formats without such structure are checked for being non-empty.
"""

from __future__ import annotations

import struct
import zipfile
import zlib
from pathlib import Path
from typing import Callable, TypeVar

from ..writing.atomic import atomic_target
from ..errors import SplatglError

T = TypeVar("T")

#: Bytes read at a time when inflating a gzip stream to its end.
_CHUNK = 1 << 20


def write_checked(path: str | Path, write: Callable[[Path], T]) -> T:
    """``write(tmp)`` to the temporary of ``path``, checked (:func:`written_problem`), then
    renamed onto ``path`` (:func:`splatgl.writing.atomic.atomic_target`); returns what ``write``
    returns.  A failed or short write raises one line naming ``path`` (never the temporary)
    and leaves nothing behind."""
    with atomic_target(path, written_problem) as tmp:
        value = write(tmp)
    return value


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
