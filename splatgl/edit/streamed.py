"""Binary PLY files larger than memory, a block of rows at a time (issue 41 item 5): the
reader of decoded blocks, the memory budget's block size and the PLY writer of blocks that
``splatgl edit``, ``convert`` and ``info --stats`` use (:mod:`.streamed_edit`,
:mod:`.streamed_stats`; other outputs :mod:`.streamed_outputs`, the operations that need
neighbours :mod:`.streamed_neighbours`).

Reading: :class:`~splatgl.lod.ply_rows.PlyRows` (the level-of-detail build's reader of row
blocks) gives the records; :meth:`Source.blocks` decodes each block as
:func:`splatgl.formats.ply.read` decodes the whole file (the same columns, the other
properties in their stored types, the rows validated, or with ``drop_invalid`` dropped by the
loaders' rule), so a block is a :class:`Scene` of consecutive input rows.  Only binary INRIA PLY
(fixed-size rows) streams; other formats are compressed or ordered as a whole and load whole.

Writing: :func:`write_blocks` writes the header with the final count first, then each block's
records (:func:`splatgl.formats.ply_write.scene_to_vertices`, little endian), into the atomic
temporary of :mod:`splatgl.writing.atomic`: the file appears complete or not at all (a failure,
Ctrl-C or SIGTERM removes the temporary).  The bytes are the in-memory writer's.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from ..errors import SceneFormatError, SplatglError
from ..formats import ply
from ..formats._memory import ACTIVATE_BYTES, scene_bytes
from ..formats.ply_write import _header, _ordered, scene_to_vertices
from ..lod.budget import MIN_WORKING, RESERVE, default_budget, format_size, resident_now
from ..lod.ply_rows import PlyRows, streamable
from ..scene.splats import MIN_QUAT_NORM, InvalidRowsDropped, Scene, SplatKind, activate
from ..writing.atomic import atomic_target, size_problem
from .attributes import Rows
from .operations import DropInvalid

#: The most rows a block holds, however large the budget (larger blocks gain nothing).
MAX_BLOCK = 1 << 18
#: Working bytes per row of a block: this many times the input record (the records read, the
#: records written, the selected copy) plus this many times the decoded float32 values (the
#: block's scene, its float64 attribute temporaries, a transform's or a merge's copy).
PER_RECORD = 3
PER_VALUE = 24
#: The normals INRIA files hold as zero placeholders.
NORMALS = ("nx", "ny", "nz")
#: What the decision compares with the budget: this many times the decoded scene (the input
#: and the edited copy the in-memory path holds at once).
IN_MEMORY_COPIES = 2


def memory_bound(memory: int | None) -> int:
    """Bytes of a ``memory`` argument: None is the commands' default (``--memory``'s, a fraction
    of this machine's RAM: :func:`splatgl.lod.budget.default_budget`)."""
    return default_budget()[0] if memory is None else int(memory)


def block_rows(budget: int, record_bytes: int, values: int, held: int | None = None,
               fixed: int = 0) -> int:
    """Rows per block within ``budget`` bytes of peak memory, for input records of
    ``record_bytes`` decoding to ``values`` float32 values; ``held``: what the process holds
    already (measured when None); ``fixed``: bytes the pass holds besides its blocks.  A
    budget leaving less than MIN_WORKING is one line."""
    held = resident_now() if held is None else held
    working = budget - held - RESERVE - fixed
    if working < MIN_WORKING:
        raise SplatglError(f"--memory {format_size(budget)} is too small: this process already "
                           f"holds {format_size(held)}; give at least "
                           f"{format_size(held + RESERVE + fixed + MIN_WORKING)}")
    per_row = PER_RECORD * record_bytes + PER_VALUE * values
    return int(min(max(working // per_row, 1), MAX_BLOCK))


class Source:
    """One binary PLY input read block by block: ``count`` rows in the file, ``kind``,
    ``sh_degree``, ``extra_dtype`` (its other properties, None for none), ``dropped`` (rows
    dropped by ``drop_invalid`` in the last complete pass)."""

    def __init__(self, path: Path, drop_invalid: bool = False):
        self.path = Path(path)
        self.rows = PlyRows(self.path, surfels=True)
        self.count, self.dtype = self.rows.count, self.rows.dtype
        plan = ply._Columns(self.path, self.rows.names, 0, self.dtype)
        self.kind = SplatKind.SURFEL_2D if plan.surfel else SplatKind.GAUSSIAN_3D
        self.coeffs = plan.sh.shape[1]
        self.sh_degree = int(round(self.coeffs ** 0.5)) - 1
        self.extra_dtype = plan.extra_dtype
        #: Whether the other properties are normals only (then, as in the reader, they are
        #: kept only where one is not zero: :meth:`use_extras`).
        self.normals_only = self.extra_dtype is not None and set(
            self.extra_dtype.names) <= set(NORMALS)
        self.extras = None if self.normals_only else self.extra_dtype
        self.drop_invalid = drop_invalid
        self.dropped = 0
        self.block = 1 << 16  # rows per block of the last pass (:meth:`blocks`)
        #: Whether a stored normal is not zero (None: not looked at), :meth:`normals_nonzero`.
        self.nonzero_normals: bool | None = None
        self.values = 11 + 3 * self.coeffs + (0 if self.extra_dtype is None else
                                              self.extra_dtype.itemsize // 4)

    def in_memory_bytes(self) -> int:
        """Bytes the decoded scene takes in memory (with the loader's temporaries)."""
        extra = 0 if self.extra_dtype is None else self.extra_dtype.itemsize
        return scene_bytes(self.count, self.coeffs) + self.count * (ACTIVATE_BYTES + extra)

    def use_extras(self, nonzero_normals: bool) -> None:
        """Keep the normals as the reader does: only when one of them is not zero."""
        if self.normals_only:
            self.extras = self.extra_dtype if nonzero_normals else None

    def normals_nonzero(self, rows: int) -> bool:
        """Whether any stored normal is not zero (one pass over the records)."""
        names = [n for n in NORMALS if self.extra_dtype is not None and
                 n in self.extra_dtype.names]
        return any(bool(np.any(records[n] != 0)) for _, records in self.rows.blocks(rows)
                   for n in names)

    def blocks(self, rows: int, warn: bool = True):
        """``(first, scene)`` per block of at most ``rows`` rows: ``first`` is the input row
        (after ``drop_invalid``'s drops) of the block's row 0; blocks left empty by
        ``drop_invalid`` are skipped.  ``dropped`` counts the rows dropped, which ``warn``
        reports at the end as the reader does (:class:`InvalidRowsDropped`)."""
        first = 0
        self.dropped = 0
        self.block = rows
        for start, records in self.rows.blocks(rows):
            scene = self.decode(records, start)
            if scene is None:
                continue
            yield first, scene
            first += scene.count
        if self.drop_invalid and self.dropped:
            if first == 0:  # the reader's words
                raise SceneFormatError(self.path, f"all {self.count} rows are invalid; nothing "
                                                  "left to render")
            if warn:
                warnings.warn(InvalidRowsDropped(self.path, self.dropped, self.count),
                              stacklevel=2)

    def decode(self, records: np.ndarray, start: int) -> Scene | None:
        """The validated :class:`Scene` of ``records`` (file rows from ``start``), as the
        reader decodes them; with ``drop_invalid``, the valid rows (None for none)."""
        n = records.shape[0]
        plan = ply._Columns(self.path, self.rows.names, n, self.dtype)
        plan.fill(records, 0)
        extras = None
        if self.extras is not None:
            extras = plan.extras if plan.extras is not None else np.zeros(n, self.extras)
        raw = Scene(plan.means, plan.quats, plan.log_scales, plan.opacity, plan.sh, self.kind,
                    extras=extras)
        if self.drop_invalid:
            with np.errstate(all="ignore"):
                keep = DropInvalid().keep(Rows(raw, 0, n))
            self.dropped += int(n - keep.sum())
            if not keep.any():
                return None
            if not keep.all():
                raw = raw.subset(keep)
        try:
            return activate(self.path, raw.means, raw.quats, raw.log_scales, raw.opacity_logits,
                            raw.sh, self.kind, extras=raw.extras)
        except SceneFormatError:  # what the reader says of the whole file, not of this block
            raise self._invalid_rows() from None

    def _invalid_rows(self) -> SceneFormatError:
        """The reader's error for the file's invalid rows: the first field (in
        :func:`activate`'s order) holding any, how many, and the first row (a pass)."""
        checks = [("position", "hold NaN or Inf"), ("rotation", "hold NaN or Inf"),
                  ("scale", "hold NaN or Inf"), ("opacity", "hold NaN or Inf"),
                  ("sh", "hold NaN or Inf"), ("rotation", "have a zero or degenerate quaternion")]
        found = [[0, None] for _ in checks]
        for start, records in self.rows.blocks(self.block):
            plan = ply._Columns(self.path, self.rows.names, records.shape[0], self.dtype)
            plan.fill(records, 0)
            q = plan.quats.astype(np.float64)
            with np.errstate(invalid="ignore", over="ignore"):
                norms = np.sqrt((q * q).sum(axis=1))
            n = records.shape[0]
            masks = [~np.isfinite(a.reshape(n, -1)).all(axis=1) for a in
                     (plan.means, plan.quats, plan.log_scales, plan.opacity, plan.sh)]
            masks.append(np.isfinite(norms) & (norms < MIN_QUAT_NORM))
            for entry, bad in zip(found, masks):
                if bad.any():
                    entry[0] += int(bad.sum())
                    if entry[1] is None:
                        entry[1] = start + int(np.flatnonzero(bad)[0])
        (field, what), (count, first) = next((c, f) for c, f in zip(checks, found) if f[0])
        return SceneFormatError(self.path, f"{count} row(s) {what} (first at index {first}); "
                                "use --drop-invalid to drop them", field)


def sources_of(inputs, drop_invalid: bool = False) -> list[Source] | None:
    """A :class:`Source` per input, or None where one is not a binary PLY of fixed-size rows
    holding splats (it loads whole, and the reader says what is wrong with it)."""
    out = []
    for path in inputs:
        if not streamable(path):
            return None
        try:
            out.append(Source(path, drop_invalid))
        except SplatglError:
            return None
    return out


def vertex_dtype(kind: SplatKind, sh_degree: int, extras: np.dtype | None) -> np.dtype:
    """The record the PLY writer writes for a scene of ``kind``, ``sh_degree`` and ``extras``."""
    k = (sh_degree + 1) ** 2
    nscale = 2 if kind is SplatKind.SURFEL_2D else 3
    empty = Scene(np.zeros((0, 3), np.float32), np.zeros((0, 4), np.float32),
                  np.zeros((0, nscale), np.float32), np.zeros(0, np.float32),
                  np.zeros((0, k, 3), np.float32), kind,
                  extras=None if extras is None else np.zeros(0, extras))
    return scene_to_vertices(empty).dtype


def write_blocks(output: Path, count: int, dtype: np.dtype, blocks) -> int:
    """Write the PLY of ``count`` rows of ``dtype`` whose :class:`Scene` blocks ``blocks``
    yields, atomically (see the module notes); returns the bytes written."""
    head = _header([("vertex", count, dtype)], "little", False, ("written by splatgl",))
    expected = len(head) + count * dtype.itemsize
    written = 0
    with atomic_target(output, lambda tmp: size_problem(tmp, expected)) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(head)
            for block in blocks:
                records = scene_to_vertices(block)
                if records.dtype != dtype:
                    raise AssertionError(f"block records {records.dtype} != header {dtype}")
                written += records.shape[0]
                if written > count:
                    raise AssertionError(f"more than the {count} rows the header declares")
                _ordered(records, "<").tofile(fh)
    return expected
