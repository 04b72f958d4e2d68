"""Writing a level-of-detail hierarchy (:class:`~splatgl.lod.build.LodTree`) as PlayCanvas
Streamed SOG: ``lod-meta.json`` and the SOG folders it names (layout:
:mod:`splatgl.formats.streamed_sog`), what ``splatgl lod scene.ply -o out/lod-meta.json`` writes.

Levels: Streamed SOG level ``l`` is the tree's level ``l`` (level 0: the original splats; each
level above merges ``branching`` neighbours), up to :data:`MAX_LEVELS` and no coarser than one
node per chunk.  Chunks (the tree's leaves, what a renderer streams): runs of ``span``
consecutive leaves in the tree's Morton order, ``span`` a multiple of ``branching ** (levels -
1)`` so that every node of every level written lies in exactly one chunk; a chunk's box holds
its original splats' extents (``k(o)`` times the largest scale, as the cull).  The chunks form
a balanced binary tree (boxes the union of their children's).  Units: each level's chunks, in order, packed into SOG folders
``L_i/meta.json`` of about :data:`UNIT_SPLATS` splats (a chunk is never split), each row in the
chunks' order (so ``offset`` and ``count`` address its rows).

Publishing, as a whole (``lod-meta.json`` is the switch: at every instant it names a complete set
of units, the old ones or the new ones): every unit is written into a hidden staging folder
beside the manifest and checked.  When the old manifest names none of the new folder names,
they are renamed into place and the new manifest published; otherwise a manifest naming the
staged folders is published first, then the old folders are moved aside, the new ones renamed
into place, and the final manifest published.  Unit folders only the old manifest named are
removed; a failure before the switch removes the staging folder and leaves the old output as it
was.  A unit folder name that exists but that no manifest there names is never replaced (one
line, before any work).
"""

from __future__ import annotations

import json
import os
import re
import shutil
from pathlib import Path

import numpy as np

from ..errors import SplatglError
from ..formats import sog_write, webp
from ..formats.metadata import BOX_KEY
from ..writing.atomic import atomic_write_bytes, cannot_write, size_problem, temp_path, write_error
from .build import LodTree
from .io import leaf_box

#: What the output's name ends with.
MANIFEST = "lod-meta.json"
#: Level-0 splats per chunk, at least (the default).
CHUNK_SPLATS = 16384
#: A Streamed SOG is built from the whole scene in memory: its peak, in decoded scenes (the
#: scene, the tree of about 4/3 as many nodes, each unit's encoder arrays; measured on a
#: 1.5M-splat SH0 PLY: 5.6x, 812 MB whatever --memory said).
BUILD_COPIES = 6
#: Splats per SOG unit, about (chunks are packed whole until a unit holds this many).
UNIT_SPLATS = 256 * 1024
#: Most levels written.
MAX_LEVELS = 6
#: Folder names the writers of this format give units (the only ones ever removed).
_UNIT_DIR = re.compile(r"^(\d+_\d+|env)$")


def is_streamed_sog_name(path: str | Path) -> bool:
    return Path(path).name.lower().endswith(MANIFEST)


def plan(tree: LodTree, chunk_splats: int = CHUNK_SPLATS) -> tuple[int, int]:
    """(levels written, leaves per chunk) for ``tree``."""
    if chunk_splats < 1:
        raise SplatglError(f"chunk size must be at least 1 splat, got {chunk_splats}")
    b = tree.branching
    levels = 1
    while levels < min(MAX_LEVELS, tree.levels) and b ** levels <= chunk_splats:
        levels += 1
    step = b ** (levels - 1)
    return levels, -(-chunk_splats // step) * step


def _node_rows(tree: LodTree, level: int, first: int, stop: int) -> tuple[int, int]:
    """Rows of ``tree.nodes`` of ``level`` over leaves ``first:stop``."""
    step = tree.branching ** level
    base = int(tree.offsets[level])
    return base + first // step, base + -(-stop // step)


def _chunks(tree: LodTree, levels: int, span: int) -> list[dict]:
    """Per chunk: its rows per level and its box."""
    n = tree.level_size(0)
    means = tree.nodes.means.astype(np.float64)
    radius = tree.radius.astype(np.float64)[:, None]
    out = []
    for first in range(0, n, span):
        stop = min(first + span, n)
        rows = [_node_rows(tree, level, first, stop) for level in range(levels)]
        lo = (means[first:stop] - radius[first:stop]).min(axis=0)  # the leaves' extents
        hi = (means[first:stop] + radius[first:stop]).max(axis=0)
        out.append({"rows": rows, "bound": {"min": lo.tolist(), "max": hi.tolist()}, "lods": {}})
    return out


def _units(chunks: list[dict], levels: int, unit_splats: int) -> list[tuple[str, list[tuple]]]:
    """(unit name, [(row start, row stop)]) per unit; fills each chunk's ``lods``."""
    units = []
    for level in range(levels):
        current: list[tuple] = []
        size = index = 0
        for k, chunk in enumerate(chunks):
            a, b = chunk["rows"][level]
            chunk["lods"][str(level)] = {"file": len(units), "offset": size, "count": b - a}
            current.append((a, b))
            size += b - a
            if size >= unit_splats or k == len(chunks) - 1:
                units.append((f"{level}_{index}/meta.json", current))
                current, size, index = [], 0, index + 1
    return units


def _tree(chunks: list[dict]) -> dict:
    """A balanced binary tree over ``chunks`` (in order)."""
    if len(chunks) == 1:
        return {"bound": chunks[0]["bound"], "lods": chunks[0]["lods"]}
    half = len(chunks) // 2
    kids = [_tree(chunks[:half]), _tree(chunks[half:])]
    lo = np.minimum(kids[0]["bound"]["min"], kids[1]["bound"]["min"]).tolist()
    hi = np.maximum(kids[0]["bound"]["max"], kids[1]["bound"]["max"]).tolist()
    return {"bound": {"min": lo, "max": hi}, "children": kids}


def _named_dirs(target: Path) -> set[str]:
    """The unit folders (first path parts) the manifest at ``target`` names (empty when there
    is none or it cannot be read)."""
    try:
        meta = json.loads(target.read_bytes().decode("utf-8"))
        names = [*meta.get("filenames", []), *([meta["environment"]] if meta.get("environment") else [])]
        return {Path(n).parts[0] for n in names if isinstance(n, str) and len(Path(n).parts) > 1}
    except (OSError, UnicodeDecodeError, ValueError, RecursionError, AttributeError, TypeError):
        return set()


def check_folder(target: str | Path) -> None:
    """Refuse (one line) a folder beside ``target`` named as a unit splatgl writes (``L_i``)
    that no manifest there names: never the writer's to replace.  Cheap: run before any work."""
    target = Path(target)
    named = _named_dirs(target)
    try:
        entries = sorted(os.listdir(target.parent or "."))
    except OSError:
        return  # the output check names what is wrong with the folder
    for name in entries:
        if _UNIT_DIR.match(name) and name != "env" and name not in named:
            raise SplatglError(f"{target.parent / name}: exists and {target.name} does not name "
                               "it; remove it or write the Streamed SOG to another folder")


def _put(path: Path, blob: bytes, target: Path) -> None:
    path.write_bytes(blob)
    problem = size_problem(path, len(blob))
    if problem is not None:
        raise cannot_write(target, f"{path.name}: {problem}")


def write_streamed_sog(target: str | Path, tree: LodTree, chunk_splats: int = CHUNK_SPLATS,
                       unit_splats: int = UNIT_SPLATS) -> dict:
    """Write ``tree`` as a Streamed SOG whose manifest is ``target`` (``*lod-meta.json``),
    replacing an older one there as a whole (see the module notes).  Returns the manifest."""
    target = Path(target)
    if not is_streamed_sog_name(target):
        raise SplatglError(f"{target}: a Streamed SOG's manifest is named {MANIFEST}")
    check_folder(target)
    levels, span = plan(tree, chunk_splats)
    chunks = _chunks(tree, levels, span)
    units = _units(chunks, levels, unit_splats)
    counts = [tree.level_size(0) if level == 0 else
              sum(b - a for c in chunks for a, b in [c["rows"][level]]) for level in range(levels)]
    manifest = {"version": 1, "asset": {"generator": sog_write.GENERATOR,
                                        "chunkGaussians": int(span), "chunkExtent": 0,
                                        "chunkMinGaussians": int(span)},
                "count": int(sum(counts)), "counts": [int(c) for c in counts],
                "lodLevels": levels, "lodErrors": False,
                "filenames": [name for name, _ in units], "tree": _tree(chunks)}
    # the leaves' 1-99 % box, as a .lod.ply's header records it: the file read whole and
    # streamed frame it alike (formats.metadata.manifest_box)
    lo, hi = leaf_box(tree.nodes.means[:tree.level_size(0)])
    manifest[BOX_KEY] = [float(v) for v in (*lo, *hi)]
    folder = target.parent
    staging = temp_path(folder / "lod-units")
    try:
        staging.mkdir()
        for name, ranges in units:
            rows = np.concatenate([np.arange(a, b) for a, b in ranges])
            textures, meta = sog_write.encode(tree.nodes.subset(rows), path=target)
            unit = staging / name.split("/")[0]
            unit.mkdir()
            for file, rgba in textures.items():
                _put(unit / file, webp.encode(rgba), target)
            _put(unit / "meta.json", json.dumps(meta).encode("utf-8"), target)
        _publish(target, staging, manifest)
    except OSError as exc:
        raise write_error(target, exc) from None
    finally:
        if staging.name not in _named_dirs(target):  # kept only while the manifest names it
            shutil.rmtree(staging, ignore_errors=True)
    return manifest


def _publish(target: Path, staging: Path, manifest: dict) -> None:
    folder = target.parent
    old = _named_dirs(target)
    new = {name.split("/")[0] for name in manifest["filenames"]}
    blob = json.dumps(manifest).encode("utf-8")
    if old & new:  # the old output still needs those names: switch to the staged units first
        staged = {**manifest, "filenames": [f"{staging.name}/{n}" for n in manifest["filenames"]]}
        atomic_write_bytes(target, json.dumps(staged).encode("utf-8"))
        aside = staging / ".old"
        aside.mkdir()
        for name in sorted(new):
            if (folder / name).exists():
                os.replace(folder / name, aside / name)
            os.replace(staging / name, folder / name)
    else:
        for name in sorted(new):
            os.replace(staging / name, folder / name)
    atomic_write_bytes(target, blob)
    for name in old - new:  # what only the old output named
        if _UNIT_DIR.match(name) and (folder / name).is_dir():
            shutil.rmtree(folder / name, ignore_errors=True)
