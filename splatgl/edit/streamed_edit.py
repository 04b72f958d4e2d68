"""``splatgl edit`` of binary PLY inputs larger than memory (issue 41 item 5): each input read a
block at a time (:mod:`.streamed`), placed by its transform, merged, put through the per-row
operations (crops, filters, dropping invalid rows, SH bands) and written as a PLY, never the
whole scene at once.  The file is the in-memory path's, byte for byte.

When the result's count is not known beforehand (a crop or filter, ``--drop-invalid``), a first
pass counts it (and finds every refusal: nothing is written), a second writes: the PLY header,
which comes first, holds the count.  ``--remove-floaters`` first finds the rows it removes per
spatial chunk (:mod:`.streamed_neighbours`: the in-memory set), then removes them as a row
test; ``--decimate`` splits the edit in two stages (:mod:`.streamed_stages`, where
:func:`plan_edit` decides).  The output is a PLY, ``.splat`` or ``.compressed.ply``
(:mod:`.streamed_outputs`).
"""

from __future__ import annotations

import re
from types import SimpleNamespace

import numpy as np

from ..errors import SplatglError
from ..formats.convert import EXTRAS_FORMATS, MAX_SH_DEGREE_OF_FORMAT
from ..scene.splats import activate_opacities
from .attributes import Rows
from .floaters import RemoveFloaters
from .operations import ROW_TESTS, Filter, ShDegree
from .pipeline import Step, select
from .placement import (MergeBuilder, describe_transform, merged_sh_degree, shared_extras,
                        transform_scene)
from .streamed import NORMALS, block_rows, vertex_dtype, write_blocks
from .streamed_outputs import (PIECE_SHARE, check_kind, whole_chunks, write_compressed,
                               write_splat)
from .streamed_neighbours import find_floaters, floater_rows
from .streamed_sort import (full_box_codes, record_dtype, scratch, scratch_error, sorted_runs,
                            to_records, to_scene)


class StreamedEdit:
    """One streamed edit (see the module notes): :meth:`scan` says what it does,
    :meth:`write` writes it."""

    def __init__(self, sources, transforms, operations, memory: int, warn: bool = False,
                 format_name: str = "ply", output=None):
        self.warn = warn  # InvalidRowsDropped once, in the first pass (convert; edit counts)
        self.format_name, self.output, self.memory = format_name, output, memory
        self.sources, self.transforms, self.operations = sources, transforms, operations
        kinds = {s.kind for s in sources}
        if len(kinds) > 1:
            raise SplatglError("edit: cannot merge 3DGS Gaussians with 2DGS surfels (" + ", ".join(
                f"{s.path}: {s.kind.value}" for s in sources) + ")")
        self.kind = sources[0].kind
        check_kind(output, format_name, self.kind)
        for op in operations:
            if isinstance(op, Filter):
                op.check(SimpleNamespace(kind=self.kind))
        self.rows = min(block_rows(memory, s.dtype.itemsize, s.values) for s in sources)
        moved = any(t is not None and not t.is_identity for t in transforms)
        for s in sources:  # the reader keeps normals that are all zero as no normals
            names = () if s.extra_dtype is None else s.extra_dtype.names
            if any(n in names for n in NORMALS) and (
                    len(sources) > 1 or format_name not in EXTRAS_FORMATS or
                    (s.normals_only and (moved or any(
                        s.extra_dtype[n] != np.float32 for n in names)))):
                s.nonzero_normals = s.normals_nonzero(self.rows)
            s.use_extras(s.nonzero_normals is not False)
        self.degree = merged_sh_degree([s.sh_degree for s in sources])
        self.shared = shared_extras([SimpleNamespace(extras=None if s.extras is None else
                                                     np.zeros(0, s.extras)) for s in sources])
        degree, self.details = self.degree, {}
        for j, op in enumerate(operations):
            if isinstance(op, ShDegree):
                self.details[j] = f"SH degree {degree} -> {min(degree, op.degree)}"
                degree = min(degree, op.degree)
        #: The SH degree the operations leave (:attr:`final_degree`: what the format stores).
        self.edited_degree = degree
        degree = min(degree, MAX_SH_DEGREE_OF_FORMAT.get(format_name, 3))
        self.final_degree = degree
        self.extras = self.shared if len(sources) > 1 else sources[0].extras
        self.dtype = vertex_dtype(self.kind, degree, self.extras)
        self.counted = None
        #: Per --remove-floaters (by position): the sorted input rows it removes.
        self.removed: dict[int, np.ndarray] = {}
        #: Notes the command prints (a chunked decimation's); why extras are dropped.
        self.notes: list[str] = []
        self.dropped_why = "not every input has them"

    def scan(self, progress=None, full: bool = False):
        """``(input counts, steps, result count, SH degree, extra names of the inputs)``; a
        first pass over the inputs where the count depends on the rows, or ``full`` (a dry
        run: every row read and checked as when writing, so a refusal comes before anything
        is written)."""
        if self.counted is None:
            if full or any(isinstance(op, ROW_TESTS + (RemoveFloaters,))
                           for op in self.operations) or \
                    self.sources[0].drop_invalid:
                tally = self._tally()
                for _ in self._blocks(tally, progress, self.warn):
                    pass
                self.counted = tally
            else:  # every row stays: known from the headers
                self.counted = {"inputs": [s.count for s in self.sources],
                                "ops": {j: [sum(s.count for s in self.sources)] * 2
                                        for j in range(len(self.operations))}, "out": None}
        t = self.counted
        counts = t["inputs"]
        kept = [n - d for n, d in zip(counts, t.get("dropped", [0] * len(counts)))]
        steps = [Step("drop-invalid", "NaN/Inf values or zero quaternions, on reading",
                      sum(counts), sum(kept))] if self.sources[0].drop_invalid else []
        for s, n, tr in zip(self.sources, kept, self.transforms):
            if tr is not None and not tr.is_identity:
                steps.append(Step("transform", f"{s.path}: {describe_transform(tr)}", n, n))
        for j, op in enumerate(self.operations):
            before, after = t["ops"][j]
            steps.append(Step(op.name, op.describe(), before, after, self.details.get(j, "")))
        count = sum(kept) if not self.operations else t["ops"][len(self.operations) - 1][1]
        names = []
        for s in self.sources:
            own = () if s.extra_dtype is None else s.extra_dtype.names
            names += [n for n in own if n not in names and (n not in NORMALS or
                                                            s.nonzero_normals)]
        return counts, steps, count, self.final_degree, names

    def write(self, output, count: int, progress=None, trip=None) -> int:
        """Write the result (``count`` rows, from :meth:`scan`) to ``output`` in its format
        (:mod:`.streamed_outputs`); its bytes.  ``trip``: a :class:`RoundTrip` given each
        piece written and what a reader gets back of it (not for PLY)."""
        if self.format_name == "splat":
            return write_splat(output, count, self._blocks(self._tally(), progress), trip)
        if self.format_name == "compressed_ply":
            lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
            for block in self._blocks(self._tally(), progress):  # the bounding box first
                lo = np.minimum(lo, block.means.min(axis=0))
                hi = np.maximum(hi, block.means.max(axis=0))
            dtype = record_dtype(self.kind, (self.final_degree + 1) ** 2)
            try:  # the scratch files' failures (a full disk) name the output, in one line
                with scratch(output) as folder:
                    recs = (to_records(b, full_box_codes(b.means, lo.astype(np.float64),
                                                         hi.astype(np.float64)), dtype)
                            for b in self._blocks(self._tally(), progress))
                    piece = max(1, self.rows // PIECE_SHARE)
                    runs = sorted_runs(folder, dtype, recs, piece, piece, count)
                    return write_compressed(output, count, whole_chunks(
                        to_scene(r, self.kind) for r in runs), trip)
            except OSError as exc:
                raise scratch_error(output, exc) from None
        return write_blocks(output, count, self.dtype, self._blocks(self._tally(), progress))

    def _tally(self) -> dict:
        return {"inputs": [s.count for s in self.sources], "dropped": [0] * len(self.sources),
                "ops": {j: [0, 0] for j in range(len(self.operations))}}

    def _inputs(self, tally: dict | None = None, progress=None, warn: bool = False):
        """``(first, block)``: the placed, merged input blocks; ``first`` the merged input row
        of the block's row 0 (what 'index' reads)."""
        first = 0
        total = sum(s.count for s in self.sources)
        done = 0
        for i, (s, tr) in enumerate(zip(self.sources, self.transforms)):
            for own, block in s.blocks(self.rows, warn):
                block = _placed(block, tr, own, f"--transform of {s.path}")
                if len(self.sources) > 1:
                    merged = MergeBuilder(block.count, self.degree, self.kind, self.shared)
                    merged.add(block)
                    block = merged.scene()
                yield first, block
                first += block.count
                if progress is not None:
                    done = min(done + self.rows, total)
                    progress(done, total, f"editing {s.path.name}")
            if tally is not None:
                tally["dropped"][i] = s.dropped

    def _floaters(self, progress=None) -> None:
        """Find the rows each ``--remove-floaters`` removes, per spatial chunk, in order
        (:func:`~.streamed_neighbours.find_floaters`)."""
        for j, op in enumerate(self.operations):
            if not isinstance(op, RemoveFloaters) or j in self.removed:
                continue

            def kept(j=j):
                for first, block in self._inputs(progress=progress):
                    keep = self._keep(block, first, j)
                    yield (first + np.flatnonzero(keep), block.means[keep],
                           activate_opacities(block.opacity_logits[keep], block.quats[keep]))
            run = floater_rows(self.memory, op.neighbours, self.rows)
            try:
                with scratch(self.output) as folder:
                    self.removed[j], found = find_floaters(op, kept, folder, run)
            except OSError as exc:
                raise scratch_error(self.output, exc) from None
            self.details[j] = found.detail()

    def _blocks(self, tally: dict, progress=None, warn: bool = False):
        """The result's blocks, in order, each checked; ``tally`` gets the counts."""
        self._floaters(progress)
        for first, block in self._inputs(tally, progress, warn):
            out = self._edited(block, first, tally)
            _nonfinite(out, tally.setdefault("out", 0), tally.setdefault("bad", {}))
            tally["out"] += out.count
            if out.count:
                yield out
        for name in FIELDS:  # the first field holding any, as the in-memory check names it
            if name in tally.get("bad", {}):
                raise SplatglError(f"edit: the result's field '{name}' holds NaN or Inf (first "
                                   f"at row {tally['bad'][name]:,}); nothing written")

    def _edited(self, block, first: int, tally: dict):
        return select(block, self._keep(block, first, len(self.operations), tally),
                      self.final_degree)

    def _keep(self, block, first: int, stop: int, tally: dict | None = None) -> np.ndarray:
        """Which rows of ``block`` the operations before ``stop`` keep."""
        keep = np.ones(block.count, bool)
        for j, op in enumerate(self.operations[:stop]):
            counts = [0, 0] if tally is None else tally["ops"][j]
            counts[0] += int(keep.sum())
            if isinstance(op, ROW_TESTS):
                keep &= op.keep(Rows(block, 0, block.count, first))
            elif isinstance(op, RemoveFloaters):
                gone = self.removed[j]
                rows = first + np.arange(block.count)
                at = np.minimum(np.searchsorted(gone, rows), max(gone.size - 1, 0))
                keep &= ~((gone[at] == rows) if gone.size else np.zeros(block.count, bool))
            counts[1] += int(keep.sum())
        return keep


def _placed(block, transform, first: int, what: str):
    """``block`` placed by ``transform``; a splat moved beyond float32 named by its input row."""
    try:
        return transform_scene(block, transform, what)
    except SplatglError as exc:
        exc.args = (re.sub(r"moves splat ([\d,]+)", lambda m: "moves splat "
                           f"{first + int(m.group(1).replace(',', '')):,}", str(exc), count=1),)
        raise


#: The result's fields checked for NaN and Inf, in the in-memory check's order.
FIELDS = {"position": "means", "rotation": "quats", "scale": "log_scales",
          "opacity": "opacity_logits", "sh": "sh"}


def _nonfinite(scene, offset: int, bad: dict) -> None:
    """Note in ``bad`` the first result row (``offset``: the block's first) holding NaN or an
    infinity in each field, for the refusal once every block is seen."""
    for name, attr in FIELDS.items():
        arr = getattr(scene, attr)
        rows = ~np.isfinite(arr.reshape(arr.shape[0], int(np.prod(arr.shape[1:])))).all(axis=1)
        if rows.any() and name not in bad:
            bad[name] = offset + int(np.flatnonzero(rows)[0])
