"""``splatgl edit``'s work on files: read the inputs (each placed by its transform, merged in
order), apply the operations, refuse an empty result, write the output atomically."""

from __future__ import annotations

import dataclasses
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..constants import sh_coeff_count
from ..errors import SplatglError
from ..formats._memory import scene_bytes
from ..lod.budget import format_size
from ..lod.io import dropped_levels_note
from ..formats import detect_format, load_scene, save_scene, stored_bytes, writer_for
from ..formats.convert import (EMPTY_FORMATS, EXTRAS_FORMATS, MAX_SH_DEGREE_OF_FORMAT,
                               dropped_note, extra_properties)
from ..scene.splats import InvalidRowsDropped
from ..scene.transform import SceneTransform
from ..writing.outputs import check_output_path
from ..progress import default_progress
from .pipeline import Step, apply_operations
from .streamed import IN_MEMORY_COPIES, memory_bound
from .streamed_stages import plan_edit
from .placement import (MergeBuilder, describe_transform, merged_sh_degree, shared_extras,
                        transform_scene)




@dataclass(frozen=True)
class EditReport:
    """What :func:`edit_files` did (or, with ``dry_run``, would do)."""

    inputs: tuple[Path, ...]
    input_counts: tuple[int, ...]
    output: Path | None
    steps: tuple[Step, ...]
    count: int
    sh_degree: int
    dry_run: bool
    seconds: float
    output_bytes: int | None = None
    notes: tuple[str, ...] = field(default=())

    def as_dict(self) -> dict:
        return {"inputs": [{"path": str(p), "splats": n} for p, n in
                           zip(self.inputs, self.input_counts)],
                "output": None if self.output is None else str(self.output),
                "dry_run": self.dry_run, "steps": [s.as_dict() for s in self.steps],
                "splats": self.count, "sh_degree": self.sh_degree,
                "output_bytes": self.output_bytes, "seconds": self.seconds,
                "notes": list(self.notes)}


def _check_transforms(inputs, transforms):
    if transforms is None:
        return [None] * len(inputs)
    transforms = list(transforms)
    if len(transforms) != len(inputs):
        raise SplatglError(f"--transform given {len(transforms)} time(s) for {len(inputs)} "
                           "input(s): give one per input, in input order ('{}' for none)")
    for t in transforms:
        if t is not None and not isinstance(t, SceneTransform):
            raise SplatglError(f"--transform: expected a SceneTransform, got {t!r}")
    return transforms


def edit_files(inputs, output=None, operations=(), transforms=None, *, drop_invalid=False,
               allow_empty=False, force=False, dry_run=False, progress=None, spz_axes=None,
               memory=None, **writer_options) -> EditReport:
    """Read ``inputs`` (scene files), merge them, apply ``operations``, write ``output``.

    Args:
        inputs: one or more scene files; several are merged in order
            (:func:`splatgl.edit.merge_scenes`'s SH rule), each placed by its transform.
        output: the file to write (format from its extension); None only with ``dry_run``.
        operations: edit operations (:mod:`splatgl.edit`), applied in order to the merged scene.
        transforms: one :class:`SceneTransform` (or None) per input.
        drop_invalid: drop rows with NaN/Inf or zero quaternions while reading (counted as the
            first step), instead of refusing such files.
        allow_empty: write a scene of zero splats instead of refusing it.
        force: replace an existing output.  dry_run: do everything but write.
        memory: bytes (None: ``--memory``'s default, half this machine's RAM); binary PLY
            inputs whose scene would take more are
            edited a block at a time into a PLY (:mod:`splatgl.edit.streamed_edit`; the same
            file), other inputs and outputs load whole (a note says so).
    Everything that can be checked before reading is checked first (output format and folder,
    an existing output, the number of transforms); the output appears only when complete.
    """
    t0 = time.perf_counter()
    inputs = [Path(p) for p in ([inputs] if isinstance(inputs, (str, Path)) else inputs)]
    if not inputs:
        raise SplatglError("edit: give at least one input scene")
    transforms = _check_transforms(inputs, transforms)
    operations = list(operations)
    writer = None
    if output is None and not dry_run:
        raise SplatglError("edit: give an output file (-o OUT), or --dry-run")
    if output is not None:
        output = Path(output)
        writer = writer_for(output)
        if not dry_run:
            check_output_path(output, overwrite=force, inputs={"IN": inputs})
    formats = [detect_format(path).NAME for path in inputs]  # missing or unknown: before reading
    if spz_axes is not None and "spz" not in formats:
        raise SplatglError("--spz-axes applies to .spz inputs only")
    progress = progress if progress is not None else default_progress()
    levels = [n for n in map(dropped_levels_note, inputs) if n]   # a level of detail's leaves
    streamed = plan_edit(inputs, writer, operations, transforms, memory, drop_invalid,
                         writer_options, output)
    if streamed is not None:
        try:
            report = _edit_streamed(streamed, inputs, output, writer, allow_empty, dry_run,
                                    progress, t0)
        finally:
            getattr(streamed, "close", lambda: None)()  # a decimation's scratch files
        return dataclasses.replace(report, notes=tuple(levels) + report.notes)
    scene, counts, steps, extras = _read(inputs, transforms, drop_invalid, progress, spz_axes)
    edited = apply_operations(scene, operations, progress)
    del scene
    result, notes = edited.scene, levels
    limit = MAX_SH_DEGREE_OF_FORMAT.get(writer.NAME, 3) if writer is not None else 3
    if result.sh_degree > limit:
        notes.append(f"the {writer.NAME} format stores SH degree {limit} only: degrees "
                     f"{limit + 1}..{result.sh_degree} dropped")
        result = result.with_sh_degree(limit)
    steps += list(edited.steps)
    notes += _dropped_extras(extras, result, writer, steps)
    _check_finite(result)
    _refuse_empty(steps, result.count, allow_empty, writer, output)
    need = IN_MEMORY_COPIES * sum(scene_bytes(n, sh_coeff_count(result.sh_degree)) for n in counts)
    if need > memory_bound(memory):
        notes.append(f"read and edited in memory (about {format_size(need)}, over --memory "
                     f"{format_size(memory_bound(memory))}): only binary PLY inputs stream")
    size = None
    if not dry_run:
        try:
            save_scene(output, result, **writer_options)
        except OSError as exc:
            raise SplatglError(f"{output}: cannot write: {exc.strerror or exc}") from None
        size = stored_bytes(output)
    return EditReport(tuple(inputs), tuple(counts), output, tuple(steps), result.count,
                      result.sh_degree, dry_run, time.perf_counter() - t0, size, tuple(notes))


def _edit_streamed(streamed, inputs, output, writer, allow_empty, dry_run, progress,
                   t0) -> EditReport:
    """The streamed edit's report, and its output written (:mod:`.streamed_stages`)."""
    counts, steps, count, degree, names = streamed.scan(progress, full=dry_run)
    notes = []
    if streamed.edited_degree > degree:
        notes.append(f"the {writer.NAME} format stores SH degree {degree} only: degrees "
                     f"{degree + 1}..{streamed.edited_degree} dropped")
    kept = () if streamed.extras is None else streamed.extras.names
    if writer is not None and writer.NAME not in EXTRAS_FORMATS:
        note = dropped_note(list(names), writer.NAME)
    else:
        note = dropped_note([n for n in names if n not in kept], why=streamed.dropped_why)
    notes += ([note] if note else []) + streamed.notes
    _refuse_empty(steps, count, allow_empty, writer, output)
    size = None if dry_run else streamed.write(output, count, progress)
    return EditReport(tuple(inputs), tuple(counts), output, tuple(steps), count, degree,
                      dry_run, time.perf_counter() - t0, size, tuple(notes))


def _refuse_empty(steps, count: int, allow_empty: bool, writer, output) -> None:
    """Refuse an empty result unless ``allow_empty``, and one a format cannot hold."""
    if count == 0 and not allow_empty:
        culprit = next((s for s in steps if s.before and not s.after), None)
        by = f" ({culprit.name} [{culprit.parameters}] removed the last {culprit.before:,})" \
            if culprit else ""
        raise SplatglError(f"edit: no splats left{by}; nothing written (use --allow-empty to "
                           "write an empty scene)")
    if count == 0 and writer is not None and writer.NAME not in EMPTY_FORMATS:
        raise SplatglError(f"{output}: the {writer.NAME} format cannot hold zero splats; nothing "
                           f"written (write .ply or .spz for an empty scene)")


def _check_finite(scene) -> None:
    """Refuse a result holding NaN or an infinity (no file of it would load again)."""
    fields = {"position": scene.means, "rotation": scene.quats, "scale": scene.log_scales,
              "opacity": scene.opacity_logits, "sh": scene.sh}
    for name, arr in fields.items():
        flat = arr.reshape(arr.shape[0], int(np.prod(arr.shape[1:])))
        for start in range(0, flat.shape[0], 1 << 16):  # a block's temporaries at a time
            bad = ~np.isfinite(flat[start:start + (1 << 16)]).all(axis=1)
            if bad.any():
                raise SplatglError(f"edit: the result's field '{name}' holds NaN or Inf (first "
                                   f"at row {start + int(np.flatnonzero(bad)[0]):,}); nothing "
                                   "written")


def _dropped_extras(names, result, writer, steps) -> list[str]:
    """The note naming the other per-splat properties of the inputs (``names``) that the output
    does not keep (none, or one line)."""
    if writer is not None and writer.NAME not in EXTRAS_FORMATS:
        note = dropped_note(list(names), writer.NAME)
    else:
        kept = () if result.extras is None else result.extras.dtype.names
        why = ("--decimate merges splats, whose own values they were" if
               any(s.name == "decimate" for s in steps) else "not every input has them")
        note = dropped_note([n for n in names if n not in kept], why=why)
    return [note] if note else []


def _read(inputs, transforms, drop_invalid, progress, spz_axes):
    """The merged, placed scene of ``inputs``, their counts, the drop-invalid step, and the
    names of the inputs' other per-splat properties (:func:`extra_properties`)."""
    scenes, counts, dropped, total, placed, extras = [], [], 0, 0, [], []
    for path, transform in zip(inputs, transforms):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", InvalidRowsDropped)
            axes = spz_axes if detect_format(path).NAME == "spz" else None
            scene = load_scene(path, drop_invalid=drop_invalid, progress=progress, spz_axes=axes,
                               allow_empty=True)  # an --allow-empty result merges like any
        here = 0
        for w in caught:
            if isinstance(w.message, InvalidRowsDropped):
                here += w.message.dropped
            else:
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        dropped += here
        counts.append(scene.count + here)
        total += counts[-1]
        extras += [n for n in extra_properties(scene) if n not in extras]
        scenes.append(transform_scene(scene, transform, f"--transform of {path}"))
        if transform is not None and not transform.is_identity:
            placed.append(Step("transform", f"{path}: {describe_transform(transform)}",
                               scene.count, scene.count))
        del scene
    steps = [Step("drop-invalid", "NaN/Inf values or zero quaternions, on reading", total,
                  total - dropped)] if drop_invalid else []
    steps += placed
    kinds = {s.kind for s in scenes}
    if len(kinds) > 1:
        raise SplatglError(f"edit: cannot merge 3DGS Gaussians with 2DGS surfels "
                           f"({', '.join(f'{p}: {s.kind.value}' for p, s in zip(inputs, scenes))})")
    if len(scenes) == 1:
        return scenes[0], counts, steps, extras
    builder = MergeBuilder(sum(s.count for s in scenes),
                           merged_sh_degree([s.sh_degree for s in scenes]), scenes[0].kind,
                           shared_extras(scenes))
    while scenes:  # each input is released once copied
        builder.add(scenes.pop(0))
    return builder.scene(), counts, steps, extras
