"""A streamed edit with ``--decimate`` (issue 41 item 5): the operations before it stream as
:class:`~.streamed_edit.StreamedEdit` does; their result is decimated per spatial chunk
(:func:`~.streamed_neighbours.decimate_chunks`) into a binary PLY in a hidden scratch folder
beside the output; the operations after it stream from that file into the output.  The scratch
folder goes when the edit is written, or with the edit object (an error, Ctrl-C, a dry run).
"""

from __future__ import annotations

import shutil
import tempfile
import weakref
from pathlib import Path

from ..formats.ply_write import _header, scene_to_vertices
from .decimate import Decimate
from .pipeline import Step
from .streamed import IN_MEMORY_COPIES, NORMALS, Source, memory_bound, sources_of, vertex_dtype
from .streamed_edit import StreamedEdit
from .streamed_outputs import STREAMED_FORMATS, refusal, whole_write_bytes
from .streamed_neighbours import DECIMATE_NOTE, decimate_chunks
from .streamed_sort import scratch_error


def plan_edit(inputs, writer, operations, transforms, memory: int | None,
              drop_invalid: bool, writer_options: dict, output=None) -> "StreamedEdit | None":
    """The streamed edit of ``inputs`` into ``output`` when ``memory`` (bytes; None: the
    default, half this machine's RAM, :func:`~.streamed.memory_bound`) is below what the
    in-memory path would hold and every input is a binary PLY; None to edit in memory.  An
    output format that cannot stream (:data:`~.streamed_outputs.STREAMED_FORMATS`) is then
    refused in one line."""
    memory = memory_bound(memory)
    sources = sources_of(inputs, drop_invalid)
    if sources is None:
        return None
    scene = sum(s.in_memory_bytes() for s in sources)
    whole = writer is not None and writer.NAME not in STREAMED_FORMATS
    if whole and whole_write_bytes(writer.NAME, scene) > memory:   # before the in-memory path
        raise refusal(output, writer.NAME, whole_write_bytes(writer.NAME, scene), memory)
    if IN_MEMORY_COPIES * scene <= memory:
        return None
    if writer is not None and writer_options:  # a PLY's other layouts: written in memory
        return None
    if any(isinstance(op, Decimate) for op in operations):
        return StagedEdit(sources, transforms, list(operations), memory,
                          "ply" if writer is None else writer.NAME, output)
    return StreamedEdit(sources, transforms, list(operations), memory,
                        format_name="ply" if writer is None else writer.NAME, output=output)


class StagedEdit:
    """``operations`` split at the first :class:`Decimate` (see the module notes); the same
    interface as :class:`StreamedEdit` (:meth:`scan`, :meth:`write`)."""

    def __init__(self, sources, transforms, operations, memory: int, format_name: str, output):
        j = next(i for i, op in enumerate(operations) if isinstance(op, Decimate))
        self.memory, self.format_name, self.output = memory, format_name, output
        self.sources, self.warn = sources, False
        self.head = StreamedEdit(sources, transforms, operations[:j], memory)
        self.op, self.position, self.operations = operations[j], j, operations
        self.transforms = transforms
        self.rows = self.head.rows
        for s in sources:  # the names of the properties decimation drops, as the reader keeps them
            names = () if s.extra_dtype is None else s.extra_dtype.names
            if s.nonzero_normals is None and any(n in names for n in NORMALS):
                s.nonzero_normals = s.normals_nonzero(self.rows)
        self.tail: StreamedEdit | None = None
        self.scanned = None
        self.folder = Path(tempfile.mkdtemp(prefix=".splatgl-edit-", dir=None if output is None
                                            else Path(output).parent))
        self._cleanup = weakref.finalize(self, shutil.rmtree, str(self.folder), True)
        self.notes: list[str] = []
        self.dropped_why = "--decimate merges splats, whose own values they were"

    def __getattr__(self, name):  # extras, degrees: the last stage's
        if name in ("extras", "edited_degree", "final_degree") and self.tail is not None:
            return getattr(self.tail, name)
        raise AttributeError(name)

    def scan(self, progress=None, full: bool = False):
        """As :meth:`StreamedEdit.scan`; decimates into the scratch folder (once; a refusal or
        an interruption removes it)."""
        if self.scanned is None:
            try:
                self.scanned = self._scan(progress, full)
            except BaseException:
                self._cleanup()
                raise
        return self.scanned

    def _scan(self, progress, full: bool):
        self.head.warn = self.warn
        counts, steps, n, degree, names = self.head.scan(progress, full)
        target = self.op.target(n)
        if target >= n:  # nothing merged: the decimation keeps every row, as in memory
            self.tail = StreamedEdit(self.sources, self.transforms,
                                     [op for op in self.operations if op is not self.op],
                                     self.memory, format_name=self.format_name,
                                     output=self.output)
            self.tail.warn = self.warn
            self.dropped_why = self.tail.dropped_why
            counts, t_steps, count, degree, names = self.tail.scan(progress, full)
            p = self.position
            t_steps = list(t_steps)
            t_steps.insert(p + (len(t_steps) - len(self.operations) + 1),
                           Step(self.op.name, self.op.describe(), n, n, self.op.note(n)))
            return counts, t_steps, count, degree, names
        path = self.folder / "decimated.ply"
        raw = self.folder / "decimated.raw"
        dtype = vertex_dtype(self.head.kind, degree, None)
        try:
            made = self._decimate(raw, path, dtype, degree, n)
        except OSError as exc:
            raise scratch_error(self.output, exc) from None
        self.notes.append(DECIMATE_NOTE.format(rows=self.rows))
        merged = Source(path)
        merged.nonzero_normals = False  # the writer's zero placeholders: none kept, as in memory
        self.tail = StreamedEdit([merged], [None], self.operations[self.position + 1:],
                                 self.memory, format_name=self.format_name, output=self.output)
        _, t_steps, count, degree, _ = self.tail.scan(progress, full)
        steps = list(steps) + [Step(self.op.name, self.op.describe(), n, made,
                                    self.op.note(n))] + list(t_steps)
        return counts, steps, count, degree, names

    def _decimate(self, raw: Path, path: Path, dtype, degree: int, n: int) -> int:
        """Decimate the first stage's ``n`` splats per chunk into the PLY ``path``; its count."""
        made = 0
        with open(raw, "wb") as fh:
            for scene in decimate_chunks(self.op, lambda: self.head._blocks(self.head._tally()),
                                         self.head.kind, (degree + 1) ** 2, n, self.folder,
                                         self.rows):
                scene_to_vertices(scene).astype(dtype, copy=False).tofile(fh)
                made += scene.count
        with open(path, "wb") as out, open(raw, "rb") as fh:
            out.write(_header([("vertex", made, dtype)], "little", False,
                              ("written by splatgl",)))
            shutil.copyfileobj(fh, out, 1 << 20)
        raw.unlink()
        return made

    def write(self, output, count: int, progress=None, trip=None) -> int:
        try:
            return self.tail.write(output, count, progress, trip)
        finally:
            self._cleanup()

    def close(self) -> None:
        """Remove the scratch folder (after :meth:`write`, or instead of it)."""
        self._cleanup()
