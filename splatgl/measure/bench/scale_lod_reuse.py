"""Scene files of ``bench --scale --lod`` kept in its scratch folder and used again (``--scratch
DIR``): at 100M splats the scene and its level of detail take about 10 minutes before any frame
is measured, so a rerun of the frame steps reuses them.

A size's scene ``scale-N.ply`` and level of detail ``scale-N.lod.ply`` found in the folder are not
built again.  Files are written atomically, so one at its final name is complete; it is also
checked cheaply (headers and sizes): the scene's size must match its header and its header must
say N splats; the level of detail must open (:class:`~splatgl.lod.lazy.LazyLod`), hold N leaves
and the run's branching.  A file that fails is refused in one line naming it (delete it to
build it again); so is a level of detail without its scene (the scene is built again, so its
level of detail would be too).  Beside them ``build-N.json`` (:func:`write_record`) holds the
figures of the run that built them, ``{"scene": step, "build": step}``; a reused step is
``{"reused": path}``, or those figures with ``"reused": true`` (and ``"file"``).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from ...errors import SplatglError


@dataclass(frozen=True)
class Found:
    """Which of a size's files are in the scratch folder, complete: the scene, the level of detail."""

    scene: bool = False
    lod: bool = False


def scene_path(folder: Path, n: int) -> Path:
    return folder / f"scale-{n}.ply"


def lod_path(folder: Path, n: int) -> Path:
    return folder / f"scale-{n}.lod.ply"


def record_path(folder: Path, n: int) -> Path:
    return folder / f"build-{n}.json"


def _stale(path: Path, why: str) -> SplatglError:
    return SplatglError(f"--scale --lod: {path}: stale ({why}); delete it to build it again")


def _vertex_count(path: Path) -> int | None:
    from ...formats import ply

    with open(path, "rb") as fh:
        header = ply.parse_header(path, fh)
    return next((e.count for e in header.elements if e.name == "vertex"), None)


def _read_checked(path: Path, read):
    """``read()`` of a file written whole, or the one-line stale-file error naming what is
    wrong with it (cut short, unreadable)."""
    from ...formats.written import written_problem

    try:
        problem = written_problem(path)
        value = None if problem else read()
    except (OSError, SplatglError) as exc:
        problem = " ".join(str(exc).split())
    if problem:
        raise _stale(path, problem.replace(f"{path}: ", ""))
    return value


def _check_scene(path: Path, n: int) -> None:
    count = _read_checked(path, lambda: _vertex_count(path))
    if count != n:
        raise _stale(path, f"its header says {count} splats, the size is {n}")


def _lod_shape(path: Path) -> tuple[int, int]:
    from ...lod.lazy import LazyLod

    with LazyLod(path) as lazy:
        return lazy.elements["vertex"][1].count, lazy.branching


def _check_lod(path: Path, n: int, branching: int) -> None:
    leaves, built = _read_checked(path, lambda: _lod_shape(path))
    if leaves != n:
        raise _stale(path, f"{leaves} leaves, the size is {n}")
    if built != branching:
        raise _stale(path, f"branching {built}, the run's is {branching}")


def find(folder: Path, n: int, branching: int) -> Found:
    """The ``n``-splat size's complete files in ``folder``; one line for a stale one."""
    scene, lod = scene_path(folder, n), lod_path(folder, n)
    for p in (scene, lod):
        if p.exists() and not p.is_file():
            raise _stale(p, "not a file")
    if scene.exists():
        _check_scene(scene, n)
    if lod.exists():
        if not scene.exists():
            raise _stale(lod, f"its scene {scene.name} is not there to build it again")
        _check_lod(lod, n, branching)
    return Found(scene.exists(), lod.exists())


def _figures(record: dict, step: str, n: int) -> dict | None:
    """The step's figures in an earlier run's record, where they are that run's figures."""
    figures = record.get(step)
    if not isinstance(figures, dict) or not isinstance(figures.get("seconds"), (int, float)):
        return None
    if step == "build" and figures.get("leaves", n) != n:
        return None
    return {k: v for k, v in figures.items() if k not in ("reused", "file")}


def reused_steps(folder: Path, n: int, found: Found) -> dict:
    """The rows of the steps ``found`` skips (``scene`` and/or ``build``): ``{"reused": path}``,
    or build-N.json's figures with ``"reused": True`` and ``"file"``."""
    try:
        record = json.loads(record_path(folder, n).read_text())
    except (OSError, ValueError):
        record = {}
    record = record if isinstance(record, dict) else {}
    steps = {}
    for step, have, path in (("scene", found.scene, scene_path(folder, n)),
                             ("build", found.lod, lod_path(folder, n))):
        if have:
            figures = _figures(record, step, n)
            steps[step] = ({"reused": str(path)} if figures is None else
                           {**figures, "reused": True, "file": str(path)})
    return steps


def write_record(folder: Path, n: int, row: dict) -> None:
    """build-N.json after a fresh build: ``{"scene": ..., "build": ...}``, the steps' figures
    (a reused scene's from the earlier record, or ``{}`` where it had none)."""
    from ...writing.atomic import atomic_write_text

    plain = {step: {k: v for k, v in row.get(step, {}).items() if k not in ("reused", "file")}
             for step in ("scene", "build")}
    atomic_write_text(record_path(folder, n), json.dumps(plain, indent=1) + "\n")
