"""Running edit operations in order over a scene, a block of rows at a time.

Selecting operations (:data:`~splatgl.edit.operations.ROW_TESTS`) only clear bits of one (N,)
keep mask, consecutive ones in one pass over blocks of :data:`BLOCK` rows; floater removal
reads the kept centres; nothing is copied until an operation needs the kept rows as a scene
(``--decimate``) or the end, where the kept rows (and the SH bands kept) are copied once, block
by block.  Extra memory beside the input scene: the mask (1 byte a splat), one block's
temporaries, the k-d tree of the kept centres while floaters are sought, and the result.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..constants import sh_coeff_count
from ..errors import SplatglError
from ..scene.splats import Scene, activate_opacities
from .attributes import Rows
from .decimate import Decimate
from .floaters import RemoveFloaters
from .operations import ROW_TESTS, Filter, ShDegree

#: Rows per block of the selecting operations.
BLOCK = 1 << 16


@dataclass(frozen=True)
class Step:
    """What one operation did: its ``name`` and ``parameters`` (as printed), the splats
    ``before`` and ``after`` it, and ``detail`` (e.g. the floater threshold)."""

    name: str
    parameters: str
    before: int
    after: int
    detail: str = ""

    @property
    def removed(self) -> int:
        return self.before - self.after

    def as_dict(self) -> dict:
        return {"operation": self.name, "parameters": self.parameters, "before": self.before,
                "after": self.after, "removed": self.removed, "detail": self.detail}

    def line(self) -> str:
        if self.name == "transform":  # moves splats, removes none
            return f"{self.name:<16} placed  {self.after:>10,}{'':<10}    [{self.parameters}]"
        share = f" ({100.0 * self.removed / self.before:.2f}%)" if self.before else ""
        verb = "merged" if self.name == "decimate" else "removed"
        text = f"{self.name:<16} {verb} {self.removed:>10,}{share:<10} -> {self.after:,}"
        text += f"  [{self.parameters}]"
        return text + (f"  {self.detail}" if self.detail else "")


@dataclass(frozen=True)
class Edited:
    """The result of :func:`apply_operations`: the edited ``scene`` and one :class:`Step` each."""

    scene: Scene
    steps: tuple[Step, ...]


def apply_operations(scene: Scene, operations, progress=None) -> Edited:
    """Apply ``operations`` to ``scene`` in the order given (see the module notes).

    ``operations``: :class:`~splatgl.edit.operations.CropBox`, ``CropSphere``, ``Filter``,
    ``DropInvalid``, ``ShDegree``, :class:`~splatgl.edit.floaters.RemoveFloaters`,
    :class:`~splatgl.edit.decimate.Decimate`.  ``progress(done, total, what)`` follows the long
    ones (floaters, decimation).  Nothing is refused for being empty here (see
    :func:`splatgl.edit.edit_scene`).
    """
    operations = list(operations)
    for op in operations:
        if not hasattr(op, "name"):
            raise SplatglError(f"not an edit operation: {op!r}")
        if isinstance(op, Filter):
            op.check(scene)
    _check_index_order(operations)
    keep = np.ones(scene.count, bool)
    degree = scene.sh_degree
    steps: list[Step] = []
    i = 0
    while i < len(operations):
        op = operations[i]
        if isinstance(op, ROW_TESTS):
            run = [op]
            while i + len(run) < len(operations) and isinstance(operations[i + len(run)], ROW_TESTS):
                run.append(operations[i + len(run)])
            steps += _row_tests(scene, keep, run)
            i += len(run)
            continue
        before = int(keep.sum())
        if isinstance(op, RemoveFloaters):
            rows = np.flatnonzero(keep)
            found = op.find(scene.means[rows], _opacity(scene, rows), progress)
            keep[rows[found.mask]] = False
            steps.append(Step(op.name, op.describe(), before, int(keep.sum()), found.detail()))
        elif isinstance(op, Decimate):
            scene = select(scene, keep, degree)
            scene = op.apply(scene, progress)
            keep = np.ones(scene.count, bool)
            steps.append(Step(op.name, op.describe(), before, scene.count, op.note(before)))
        elif isinstance(op, ShDegree):
            new = min(degree, op.degree)
            steps.append(Step(op.name, op.describe(), before, before,
                              f"SH degree {degree} -> {new}"))
            degree = new
        else:
            raise SplatglError(f"not an edit operation: {op!r}")
        i += 1
    return Edited(select(scene, keep, degree), tuple(steps))


def _check_index_order(operations) -> None:
    """Refuse a filter reading ``index`` (the row in the input) after a --decimate, which
    renumbers the rows."""
    merged = False
    for op in operations:
        if isinstance(op, Decimate):
            merged = True
        elif isinstance(op, Filter) and merged and "index" in op.expression.names:
            raise SplatglError(f"{op.option} {op.expression.text!r}: 'index' is the splat's row "
                               "in the input, which --decimate renumbers: put this filter "
                               "before --decimate")


def _opacity(scene: Scene, rows: np.ndarray) -> np.ndarray:
    out = np.empty(rows.size)
    for s in range(0, rows.size, BLOCK):
        r = rows[s:s + BLOCK]
        out[s:s + BLOCK] = activate_opacities(scene.opacity_logits[r], scene.quats[r])
    return out


def _row_tests(scene: Scene, keep: np.ndarray, ops) -> list[Step]:
    """Run consecutive selecting operations in one pass over blocks; one Step each."""
    before = [0] * len(ops)
    after = [0] * len(ops)
    for start in range(0, scene.count, BLOCK):
        stop = min(start + BLOCK, scene.count)
        rows = Rows(scene, start, stop)
        block = keep[start:stop]
        for j, op in enumerate(ops):
            before[j] += int(block.sum())
            block &= op.keep(rows)
            after[j] += int(block.sum())
    return [Step(op.name, op.describe(), b, a) for op, b, a in zip(ops, before, after)]


def select(scene: Scene, keep: np.ndarray, degree: int) -> Scene:
    """The rows of ``scene`` where ``keep`` holds with SH bands up to ``degree``, copied once,
    block by block (``scene`` itself when nothing changes)."""
    count = int(keep.sum())
    if count == scene.count and degree == scene.sh_degree:
        return scene
    k = sh_coeff_count(degree)
    out = {name: np.empty((count,) + getattr(scene, name).shape[1:], np.float32)
           for name in ("means", "quats", "log_scales", "opacity_logits")}
    out["sh"] = np.empty((count, k, 3), np.float32)
    at = 0
    for start in range(0, scene.count, BLOCK):
        rows = slice(start, start + BLOCK)
        mask = keep[rows]
        m = int(mask.sum())
        for name, arr in out.items():
            src = getattr(scene, name)[rows]
            arr[at:at + m] = (src[:, :k] if name == "sh" else src)[mask]
        at += m
    for arr in out.values():
        arr.flags.writeable = False
    return Scene(out["means"], out["quats"], out["log_scales"], out["opacity_logits"], out["sh"],
                 scene.kind, extras=None if scene.extras is None else scene.extras[keep])
