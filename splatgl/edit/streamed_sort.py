"""Splats in a spatial order when they do not fit in memory (issue 41 item 5): the streamed
edit's blocks become fixed-size records with a Morton code, distributed to cell files by the
code's upper bits and read back in sorted runs (the out-of-core level of detail's external
radix sort, :mod:`splatgl.lod.external`: equal codes keep the order they came in).

Two orders, as in memory (:mod:`splatgl.scene.spatial`): the compressed PLY writer's
(:func:`full_box_codes`, 10 bits per axis over the bounding box, shifted to the top of the
63 bits the sort distributes) and the clamped 1-99 % box order of ``--decimate`` and the
floater chunks (:func:`splatgl.scene.spatial.morton_codes_clamped`).  Scratch files live in a
hidden folder beside the output (:func:`scratch`), removed on any exit.
"""

from __future__ import annotations

import errno
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from ..errors import SplatglError
from ..lod.budget import format_size
from ..lod.external import TOP_SHIFT, _Cells, _runs
from ..scene.spatial import box_morton_codes
from ..scene.splats import Scene, SplatKind
from ..writing.atomic import disk_note, write_error

#: Bits per axis of the compressed PLY writer's order (:func:`morton_order_full_box`'s default).
FULL_BOX_BITS = 10


@contextmanager
def scratch(near: Path | None):
    """A hidden temporary folder beside ``near`` (the output; the system's temporary folder
    for None), removed when the block is left by any way (an error, Ctrl-C, SIGTERM)."""
    folder = Path(tempfile.mkdtemp(prefix=".splatgl-edit-",
                                   dir=None if near is None else Path(near).parent))
    try:
        yield folder
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def scratch_error(output, exc: OSError) -> SplatglError:
    """The one line of a failed write of the scratch files (a full disk): naming ``output``
    (:func:`~splatgl.writing.atomic.write_error`), or for a dry run the temporary folder."""
    if output is not None:
        return write_error(output, exc)
    folder = Path(tempfile.gettempdir())
    return SplatglError(f"{folder}: cannot write the edit's scratch files "
                        f"({exc.strerror or 'the data was written only in part'})"
                        f"{disk_note(folder)}")


def record_dtype(kind: SplatKind, coeffs: int, extra: list | tuple = ()) -> np.dtype:
    """A splat's stored values with its ``code`` (uint64) and ``extra`` fields."""
    nscale = 2 if kind is SplatKind.SURFEL_2D else 3
    return np.dtype([("code", "<u8"), ("means", "<f4", 3), ("quats", "<f4", 4),
                     ("log_scales", "<f4", nscale), ("opacity_logits", "<f4"),
                     ("sh", "<f4", (coeffs, 3)), *extra])


def to_records(scene: Scene, code: np.ndarray, dtype: np.dtype) -> np.ndarray:
    """``scene``'s rows as ``dtype`` records (the extra fields zero)."""
    recs = np.zeros(scene.count, dtype)
    recs["code"] = code
    for name in ("means", "quats", "log_scales", "opacity_logits", "sh"):
        recs[name] = getattr(scene, name)
    return recs


def to_scene(recs: np.ndarray, kind: SplatKind) -> Scene:
    """The :class:`Scene` of records (their stored values, no extras)."""
    arrays = [np.ascontiguousarray(recs[n]) for n in ("means", "quats", "log_scales",
                                                       "opacity_logits", "sh")]
    for a in arrays:
        a.flags.writeable = False
    return Scene(*arrays, kind)


#: Scratch bytes a sort of N records holds at most, in records: its cell files, plus a cell
#: being split or the files a caller writes from the runs while the cells are read.
SCRATCH_RECORDS = 2


def sorted_runs(folder: Path, dtype: np.dtype, blocks, run: int, rows: int,
                total: int | None = None):
    """The records ``blocks`` yields, in code order (ties in the order given), as runs of at
    most ``run`` records; cell files under ``folder`` (read back ``rows`` at a time).  With
    ``total`` (the records to come), a file system without room for SCRATCH_RECORDS times
    their bytes is an OSError (ENOSPC, saying how much) before anything is written, so a long
    edit fails at its start, not hours in (:func:`scratch_error` makes it one line)."""
    if total is not None:
        need = SCRATCH_RECORDS * int(total) * dtype.itemsize
        free = shutil.disk_usage(folder).free
        if free < need:
            raise OSError(errno.ENOSPC, f"no room for the edit's scratch files beside it: about "
                                        f"{format_size(need)} needed, {format_size(free)} free")
    cells = _Cells(folder / "cells", TOP_SHIFT, dtype)
    for recs in blocks:
        cells.add(recs)
    yield from _runs(cells, SimpleNamespace(run=run, rows=rows))


def full_box_codes(means: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(N,) uint64 codes of :func:`splatgl.scene.spatial.morton_order_full_box` (10 bits per
    axis over the box ``lo..hi`` of every centre), moved to bits 33-62: sorting them stably
    gives that order."""
    bits = FULL_BOX_BITS
    code = box_morton_codes(means, lo, hi, bits)
    return code.astype(np.uint64) << np.uint64(63 - 3 * bits)
