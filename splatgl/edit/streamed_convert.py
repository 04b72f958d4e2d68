"""``splatgl convert`` within a memory budget (issue 41 item 5): a binary PLY larger than the
budget, written as a PLY (format change within PLY, ``--sh-degree``, ``--drop-invalid``), a
``.splat`` or a ``.compressed.ply`` (:mod:`.streamed_outputs`), goes through
:mod:`.streamed_edit` a block at a time; the round-trip error is measured by reading a PLY
output back block by block beside the input, and the other formats piece by piece from the
bytes written for each piece (:class:`~.streamed_outputs.RoundTrip`).  An output format written
whole (SPZ, SOG, glTF) is refused over the budget in one line.  Other inputs convert in
memory (:func:`splatgl.formats.convert.convert`); one over the budget then says so.
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path

import numpy as np

from ..errors import SplatglError, add_note
from ..formats import writer_for
from ..formats._memory import scene_bytes
from ..formats.convert import Conversion, conversion_error, convert, written_note
from ..lod.budget import format_size
from ..lod.io import dropped_levels_note
from ..writing.outputs import check_output_path
from .operations import ShDegree
from .streamed import IN_MEMORY_COPIES, Source, memory_bound
from .streamed_stages import plan_edit
from .streamed_outputs import STREAMED_FORMATS, RoundTrip

#: The per-attribute errors :func:`conversion_error` gives as ``{"max", "mean"}``.
_MEASURED = ("position", "scale", "opacity", "rotation", "color", "sh_rest")


def convert_file(source, output, *, memory: int | None = None, drop_invalid: bool = False,
                 sh_degree: int | None = None, force: bool = False, progress=None,
                 spz_axes: str | None = None, **writer_options) -> Conversion:
    """:func:`splatgl.formats.convert.convert`, streamed where ``memory`` (bytes; None: the
    default, half this machine's RAM) is below what loading the input would take, the input is
    a binary PLY and the output streams (see the module notes); the same file and report
    either way.  A level-of-detail input converts its finest level, with a warning
    (:func:`splatgl.lod.io.dropped_levels_note`)."""
    result = _convert_file(source, output, memory, drop_invalid, sh_degree, force, progress,
                           spz_axes, writer_options)
    note = dropped_levels_note(source)
    if note:
        warnings.warn(note, stacklevel=2)
    return result


def _convert_file(source, output, memory, drop_invalid, sh_degree, force, progress, spz_axes,
                  writer_options) -> Conversion:
    source, output = Path(source), Path(output)
    memory = memory_bound(memory)
    streamed = None
    if spz_axes is None or writer_for(output).NAME not in STREAMED_FORMATS:  # SPZ: refused
        writer_for(output)  # an unsupported extension: the converter's one line first
        check_output_path(output, overwrite=force, inputs={"IN": source})
        if sh_degree is not None and not 0 <= sh_degree <= 3:
            raise SplatglError(f"--sh-degree must be 0-3, got {sh_degree}")
        ops = [] if sh_degree is None else [ShDegree(sh_degree)]
        streamed = plan_edit([source], writer_for(output), ops, [None], memory, drop_invalid,
                             writer_options, output)
    if streamed is None:
        result = convert(source, output, drop_invalid=drop_invalid, sh_degree=sh_degree,
                         force=force, progress=progress, spz_axes=spz_axes, **writer_options)
        need = IN_MEMORY_COPIES * scene_bytes(result.count, (result.sh_degree_in + 1) ** 2)
        if need > memory:
            warnings.warn(f"{source}: converted in memory (about {format_size(need)}, over "
                          f"--memory {format_size(memory)}): only a binary PLY input streams",
                          stacklevel=2)
        return result
    t0 = time.perf_counter()
    streamed.warn = True
    name, src = streamed.format_name, streamed.sources[0]
    if streamed.edited_degree > streamed.final_degree:  # convert's words
        warnings.warn(f"{output}: the {name} format stores SH degree {streamed.final_degree} "
                      f"only; dropping SH degrees {streamed.final_degree + 1}.."
                      f"{streamed.edited_degree} of the input", stacklevel=2)
    counts, steps, count, degree, names = streamed.scan(progress)
    if name == "ply":
        size = streamed.write(output, count, progress)
        try:   # OUT is whole from here: a Ctrl-C cuts short only the report
            error = _round_trip(src, output, streamed.rows)
        except KeyboardInterrupt as exc:
            raise add_note(exc, written_note(output))
    else:
        trip = RoundTrip(writer_for(output))
        size = streamed.write(output, count, progress, trip)
        error = trip.result()
        error["sh_degree"] = [src.sh_degree, degree]  # of the input, as convert compares
        error["bit_exact"] = error["bit_exact"] and src.sh_degree == degree
        error["dropped"] = list(names)  # the input's other properties: the format holds none
    return Conversion(source, output, "ply", name, count, src.sh_degree, degree, size,
                      time.perf_counter() - t0, error)


def _round_trip(src: Source, output: Path, rows: int) -> dict:
    """:func:`conversion_error` of the written ``output`` against ``src``, block by block."""
    back = Source(output)
    back.use_extras(src.extras is not None)
    total, sums, out = 0, {}, None
    with open(output, "rb") as fh:
        fh.seek(back.rows.offset)
        for first, a in src.blocks(rows, warn=False):
            b = back.decode(np.fromfile(fh, back.dtype, a.count), first)
            e = conversion_error(a, b)
            if out is None:
                out = dict(e)
            else:
                out["bit_exact"] = out["bit_exact"] and e["bit_exact"]
                out["dropped"] += [n for n in e["dropped"] if n not in out["dropped"]]
                out["color_outside_01"] += e["color_outside_01"]
                for name in _MEASURED:
                    if e[name] is not None:
                        out[name] = {"max": max(out[name]["max"], e[name]["max"]),
                                     "mean": out[name]["mean"]}
            for name in _MEASURED:
                if e[name] is not None:
                    sums[name] = sums.get(name, 0.0) + e[name]["mean"] * a.count
            total += a.count
    out["count"] = total
    for name in _MEASURED:
        if out[name] is not None:
            out[name]["mean"] = sums[name] / total
    out["bounds"] = None
    out["within_bounds"] = None
    return out
