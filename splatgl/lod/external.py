"""The out-of-core level of detail: ``splatgl lod`` on a scene larger than memory, within a budget
(:mod:`splatgl.lod.budget`), writing the same ``.lod.ply`` as :func:`build_hierarchy` and
:func:`splatgl.lod.io.write_lod` (byte for byte).

The hierarchy is implicit (:mod:`splatgl.lod.build`): the leaves in Morton order, each level
merging consecutive groups of B.  So ``B ** k`` consecutive leaves (a *chunk*, spatially
compact because Morton-ordered) are a whole subtree of k levels, built alone; the levels above
are built over the chunks' roots.  Float64 moments and radii of the roots are carried over, so
every value is the one the in-memory build computes.  The passes over the input (binary PLY,
read block by block, :mod:`splatgl.lod.ply_rows`):

1. validate every row, and histogram the centres (the 1-99 % box, first pass);
2. the box's order statistics exactly (second pass);
3. Morton codes, rows distributed to cell files by the codes' upper bits (an external radix
   sort: a cell larger than a run is split again by the next bits);
4. cells in code order, each sorted in memory, feed the chunks; each chunk's leaves go to the
   output and its levels to one file per level, appended at the end, with the bounds.

Temporary files live in a hidden folder beside the output, removed on any exit (errors, Ctrl-C,
SIGTERM); the output is written to its atomic temporary (:mod:`splatgl.writing.atomic`), checked,
then renamed.
"""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

import numpy as np

from ..errors import SplatglError
from ..formats import ply_write
from ..formats.written import written_problem
from ..scene.splats import Scene
from ..scene.spatial import morton_codes_clamped
from ..writing.atomic import atomic_target
from .budget import Plan, format_size
from .build import (MAX_LOG_SCALE, concat_nodes, leaf_moments, level_offsets, merge_groups,
                    own_extents, propagate_radii)
from .io import BOUNDS, COMMENTS, ELEMENT, bounds_rows
from .ply_rows import BoxFinder, PlyRows

#: Bits of the Morton code per distribution pass (512 cells), from the top of its 63.
CELL_BITS = 9
TOP_SHIFT = 63 - CELL_BITS
#: Progress units per input row of each phase (scan, box, distribution, chunks).
PHASES = (1, 1, 1, 3)


class _Progress:
    """One meter over the phases (``progress(done, total, what)``), so its time left covers them all."""

    def __init__(self, progress, count: int):
        self.progress, self.count = progress, count
        self.total = sum(PHASES) * count
        self.base = 0

    def phase(self, index: int) -> None:
        self.base = sum(PHASES[:index]) * self.count

    def __call__(self, rows: int, phase: int, what: str) -> None:
        if self.progress is not None:
            self.progress(min(self.base + PHASES[phase] * rows, self.total), self.total, what)


def _check_scales(scene: Scene, first: int) -> None:
    big = np.flatnonzero((scene.log_scales > MAX_LOG_SCALE).any(axis=1))
    if big.size:  # as build_hierarchy says it
        raise SplatglError(f"level of detail: splat {first + int(big[0]):,} has a scale above "
                           f"e^{MAX_LOG_SCALE} world units, whose moments overflow: remove "
                           "such splats first (splatgl edit --remove 'max_scale > 1e38')")


def _means(records: np.ndarray) -> np.ndarray:
    """(K, 3) float64 centres of raw records, through float32 as the reader stores them."""
    return np.stack([records[c].astype(np.float32) for c in "xyz"], axis=1).astype(np.float64)


class _Cells:
    """Rows distributed by ``(code >> shift) & 511`` into one file per cell under ``folder``."""

    def __init__(self, folder: Path, shift: int, dtype: np.dtype):
        self.folder, self.shift, self.dtype = folder, shift, dtype
        folder.mkdir()
        self.files: dict[int, object] = {}
        self.counts: dict[int, int] = {}

    def add(self, recs: np.ndarray) -> None:
        cell = ((recs["code"] >> np.uint64(self.shift)) & np.uint64(511)).astype(np.int64)
        order = np.argsort(cell, kind="stable")  # rows keep their input order within a cell
        cell = cell[order]
        cuts = np.concatenate([[0], np.flatnonzero(np.diff(cell)) + 1, [cell.size]])
        for a, b in zip(cuts[:-1], cuts[1:]):
            c = int(cell[a])
            if c not in self.files:
                self.files[c] = open(self.folder / f"{c:03d}", "wb")
                self.counts[c] = 0
            self.files[c].write(recs[order[a:b]].tobytes())
            self.counts[c] += int(b - a)

    def close(self) -> list[tuple[Path, int]]:
        """The cells' ``(file, rows)`` in code order."""
        for fh in self.files.values():
            fh.close()
        return [(self.folder / f"{c:03d}", self.counts[c]) for c in sorted(self.files)]


def file_blocks(path: Path, dtype: np.dtype, rows: int):
    """The records of type ``dtype`` in the file at ``path``, ``rows`` at a time."""
    with open(path, "rb") as fh:
        while True:
            block = np.fromfile(fh, dtype, rows)
            if not block.size:
                return
            yield block


def _runs(cells: _Cells, plan: Plan):
    """Sorted runs (by code, then input row) of at most ``plan.run`` rows, in code order."""
    pending: list[Path] = []
    held = 0
    for path, n in cells.close():
        if n > plan.run or held + n > plan.run:
            if pending:
                yield _sorted_run(pending, cells.dtype)
                pending, held = [], 0
        if n <= plan.run:
            pending.append(path)
            held += n
        elif cells.shift == 0:  # one code: already in input order
            yield from file_blocks(path, cells.dtype, plan.run)
            path.unlink()
        else:  # split by the next bits
            sub = _Cells(path.with_name(path.name + "d"), max(cells.shift - CELL_BITS, 0), cells.dtype)
            for block in file_blocks(path, cells.dtype, plan.rows):
                sub.add(block)
            path.unlink()
            yield from _runs(sub, plan)
    if pending:
        yield _sorted_run(pending, cells.dtype)


def _sorted_run(paths: list[Path], dtype: np.dtype) -> np.ndarray:
    data = np.concatenate([np.fromfile(p, dtype) for p in paths])
    for p in paths:
        p.unlink()
    return data[np.argsort(data["code"], kind="stable")]


class _Chunks:
    """Builds the chunks' subtrees (``k`` levels over ``window`` leaves each) and the levels
    above them, writing the pieces: leaves into ``out``, level ``l`` and bounds into files."""

    def __init__(self, rows: PlyRows, out, folder: Path, branching: int, window: int, k: int):
        self.rows, self.out, self.branching, self.window, self.k = rows, out, branching, window, k
        self.level_files = [open(folder / f"level{l}", "wb") for l in range(1, k + 1)]
        self.bound_files = [open(folder / f"bounds{l}", "wb") for l in range(k + 1)]
        self.roots: list[tuple] = []  # per chunk: float64 state, root row (Scene), radius

    def chunk(self, recs: np.ndarray) -> None:
        b = self.branching
        leaves = self.rows.scene(recs["rec"])
        state = leaf_moments(leaves)
        levels, sizes = [], [leaves.count]
        for _ in range(self.k):  # k merges even past one node: the whole tree's last groups do
            p_mu, p_cov, p_opac, p_area, p_sh, p_scales, p_quat, _ = merge_groups(*state, b)
            levels.append((p_mu, p_quat, p_scales, p_opac, p_sh))
            state = (p_mu, p_cov, p_opac, p_area, p_sh)
            sizes.append(p_mu.shape[0])
        nodes = concat_nodes(leaves, levels)
        offs = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        radius = propagate_radii(nodes.means.astype(np.float64), own_extents(nodes), offs, b)
        ply_write.scene_to_vertices(leaves, normals=False).tofile(self.out)
        for level in range(self.k + 1):
            lo, hi = int(offs[level]), int(offs[level + 1])
            if level:
                part = nodes.subset(slice(lo, hi))
                ply_write.scene_to_vertices(part, normals=False).tofile(self.level_files[level - 1])
            bounds_rows(nodes.means[lo:hi], radius[lo:hi]).tofile(self.bound_files[level])
        root = slice(int(offs[-2]), int(offs[-1]))
        self.roots.append((tuple(a[:1] for a in state), nodes.subset(root), radius[root]))

    def finish(self, folder: Path) -> None:
        """The levels above the chunks, then every level and the bounds appended to ``out``."""
        for fh in self.level_files + self.bound_files:
            fh.close()
        b = self.branching
        state = tuple(np.concatenate([r[0][i] for r in self.roots]) for i in range(5))
        levels = []
        while state[0].shape[0] > 1:
            p_mu, p_cov, p_opac, p_area, p_sh, p_scales, p_quat, _ = merge_groups(*state, b)
            levels.append((p_mu, p_quat, p_scales, p_opac, p_sh))
            state = (p_mu, p_cov, p_opac, p_area, p_sh)
        roots = self.roots[0][1] if len(self.roots) == 1 else _concat_scenes([r[1] for r in self.roots])
        top = concat_nodes(roots, levels)
        offs = level_offsets(roots.count, b)
        radius = own_extents(top)
        radius[:roots.count] = np.concatenate([r[2] for r in self.roots])
        radius = propagate_radii(top.means.astype(np.float64), radius, offs, b)
        for level in range(1, self.k + 1):
            _append(folder / f"level{level}", self.out)
        upper = slice(roots.count, None)
        ply_write.scene_to_vertices(top.subset(upper), normals=False).tofile(self.out)
        for level in range(self.k + 1):
            _append(folder / f"bounds{level}", self.out)
        bounds_rows(top.means[upper], radius[upper]).tofile(self.out)


def _concat_scenes(scenes: list[Scene]) -> Scene:
    return Scene(*(np.concatenate([getattr(s, f) for s in scenes])
                   for f in ("means", "quats", "log_scales", "opacity_logits", "sh")))


def _append(path: Path, out) -> None:
    with open(path, "rb") as src:
        shutil.copyfileobj(src, out, 1 << 20)
    path.unlink()


def _check_space(out: Path, need: int) -> None:
    """One line before the work where the output's file system cannot hold ``need`` bytes (the
    temporaries and the output); a disk that fills during the build says so too
    (:func:`splatgl.output.atomic.write_error`)."""
    try:
        free = shutil.disk_usage(out.parent).free
    except OSError:
        return  # the write says why
    if free < need:
        raise SplatglError(f"{out}: cannot write: the build needs about {format_size(need)} free "
                           f"beside it (temporary files and the output), {format_size(free)} free")


def build_lod_file(src: Path, out: Path, branching: int, plan_for, progress=None) -> dict:
    """Build the level of detail of the binary PLY ``src`` into ``out`` (``*.lod.ply``) within
    the budget ``plan_for(record_bytes, count)`` gives (a :class:`~splatgl.lod.budget.Plan`).
    Returns ``{"leaves", "parents", "levels", "chunks", "window"}``."""
    rows = PlyRows(src)
    n = rows.count
    plan = plan_for(rows.dtype.itemsize, n)
    meter = _Progress(progress, n)
    box = BoxFinder(n)
    what = f"lod {Path(src).name}"
    for start, block in rows.blocks(plan.rows):  # 1: validate, first histogram
        scene = rows.scene(block, start)
        _check_scales(scene, start)
        box.add_first(scene.means)
        meter(start + block.shape[0], 0, what + ": checking")
    meter.phase(1)
    for start, block in rows.blocks(plan.rows):  # 2: the box's order statistics
        box.add_second(_means(block).astype(np.float32))
        meter(start + block.shape[0], 1, what + ": bounds")
    lo, hi = box.box()
    offsets = level_offsets(n, branching)
    window, k = plan.window, 0
    while branching ** (k + 1) <= window:
        k += 1
    window = branching ** k
    if window >= n:  # one chunk: the whole tree
        k = len(offsets) - 2
        window = n
    one = rows.scene(next(rows.blocks(1))[1])
    vertex = ply_write.scene_to_vertices(one, normals=False).dtype
    header = ply_write._header([("vertex", n, vertex), (ELEMENT, int(offsets[-1]) - n, vertex),
                                (BOUNDS, int(offsets[-1]), bounds_rows(one.means, np.zeros(1)).dtype)],
                               "little", False, COMMENTS(branching, lo, hi))
    rec = np.dtype([("code", "<u8"), ("idx", "<i8"), ("rec", rows.dtype)])
    out = Path(out)
    _check_space(out, n * rec.itemsize + 2 * (len(header) + int(offsets[-1]) * (vertex.itemsize + 16)))
    with atomic_target(out, written_problem) as tmp, tempfile.TemporaryDirectory(
            prefix=f".{out.name}.lodtmp", dir=out.parent) as scratch, open(tmp, "wb") as fh:
        folder = Path(scratch)
        meter.phase(2)
        cells = _Cells(folder / "cells", TOP_SHIFT, rec)
        for start, block in rows.blocks(plan.rows):  # 3: distribute by code
            recs = np.empty(block.shape[0], rec)
            recs["code"] = morton_codes_clamped(_means(block), lo, hi)
            recs["idx"] = np.arange(start, start + block.shape[0])
            recs["rec"] = block
            cells.add(recs)
            meter(start + block.shape[0], 2, what + ": sorting")
        meter.phase(3)
        fh.write(header)
        chunks = _Chunks(rows, fh, folder, branching, window, k)
        pending, done = None, 0  # pending: the rows short of a chunk, carried to the next run
        for run in _runs(cells, plan):  # 4: chunks in Morton order
            pos = 0
            if pending is not None:
                pos = window - pending.shape[0]
                if run.shape[0] < pos:
                    pending = np.concatenate([pending, run])
                    continue
                chunks.chunk(np.concatenate([pending, run[:pos]]))
                pending, done = None, done + window
            while run.shape[0] - pos >= window:
                chunks.chunk(run[pos:pos + window])
                pos, done = pos + window, done + window
                meter(done, 3, what + ": building")
            pending = run[pos:].copy() if pos < run.shape[0] else None
            del run
        if pending is not None:
            chunks.chunk(pending)
        chunks.finish(folder)
        meter(n, 3, what + ": building")
    return {"leaves": n, "parents": int(offsets[-1]) - n, "levels": len(offsets) - 1,
            "chunks": len(chunks.roots), "window": window}
