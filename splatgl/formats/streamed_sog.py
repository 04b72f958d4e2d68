"""PlayCanvas Streamed SOG (``lod-meta.json`` and the SOG folders it names): reader.

What splat-transform 3.x writes for ``splat-transform scene.ply out/lod-meta.json`` and PlayCanvas
streams.  ``lod-meta.json`` (``version`` 1, or none in older files) holds:

- ``lodLevels``: the number of levels; level 0 is the finest (every splat of the scene), each
  further level a coarser stand-in for the whole scene.
- ``counts`` (optional): the splats of each level; ``count`` their sum.
- ``filenames``: the SOG units, paths relative to ``lod-meta.json``'s folder, each a SOG version 2
  folder (``L_i/meta.json`` and its WebP textures, :mod:`splatgl.formats.sog`) holding splats of
  one level only.
- ``tree``: a binary tree of axis-aligned ``bound`` boxes (``{"min": [x, y, z], "max": [...]}``,
  the splats' extents) whose inner nodes have ``children`` and whose leaves (the chunks streamed)
  have ``lods``: level -> ``{"file": index into filenames, "offset": first row in that unit,
  "count": rows}``; optionally ``errors`` (one per level, ``lodErrors`` true when every leaf has
  them).
- ``environment`` (optional): one more SOG folder of splats drawn at every level (a skybox).
- ``splatglFramingBox`` (optional, written by ``splatgl lod`` only; other readers ignore it):
  ``[x0, y0, z0, x1, y1, z1]``, the 1-99 % box of the finest level's centres, which frames the
  file alike read whole and streamed (:func:`splatgl.formats.metadata.manifest_box`; a
  ``.lod.ply`` records the same box in its header).  Without it a streamed file frames its
  chunks' box, and read whole its splats' 1-99 % box.

Both store the PLY axes (the scene's own).  :func:`read_structure` reads the manifest only
(levels, chunks with bounds, for a streaming renderer); :meth:`StreamedSog.load` decodes one
level (or chosen chunks of it); :func:`read` loads the finest level as a scene.  The writer is
:mod:`splatgl.lod.streamed_sog_write`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import SceneFormatError
from ..scene.splats import Scene
from . import _binary, sog
from .metadata import manifest_box

NAME = "streamed-sog"
EXTENSIONS = ("lod-meta.json",)
#: The manifest versions read (None: written before splat-transform stamped one).
VERSIONS = (None, 1)
#: Deepest tree read (a corrupt file cannot exhaust the stack).
MAX_DEPTH = 200


def sniff(head: bytes) -> bool:
    """JSON with a ``lodLevels`` key near its start (splat-transform writes it before the tree)."""
    return head.lstrip().startswith(b"{") and b'"lodLevels"' in head


@dataclass(frozen=True)
class Chunk:
    """A leaf of the tree: a region streamed as a whole.

    Attributes:
        bound_min, bound_max: (3,) float64 corners of its box (PLY axes).
        lods: level -> (file index, first row, rows) of its splats at that level.
        errors: its error per level, or None.
    """

    bound_min: np.ndarray
    bound_max: np.ndarray
    lods: dict
    errors: tuple | None = None

    def count(self, level: int) -> int:
        return self.lods[level][2] if level in self.lods else 0


@dataclass(frozen=True)
class StreamedSog:
    """A Streamed SOG's manifest: what a streaming renderer needs before reading any splat."""

    path: Path
    levels: int
    counts: tuple
    filenames: tuple
    chunks: tuple
    environment: str | None = None
    #: The framing box the manifest records (``(lo, hi)`` float64), or None.
    box: tuple | None = None

    def unit_path(self, name: str, field: str) -> Path:
        """The ``meta.json`` of a unit named ``name`` (relative, inside the manifest's folder)."""
        parts = Path(name).parts
        if (not name or Path(name).is_absolute() or ".." in parts or "\\" in name
                or not name.lower().endswith("meta.json")):
            raise SceneFormatError(self.path, f"unit {name!r} is not a relative path to a SOG "
                                              "meta.json inside the folder", field)
        return self.path.parent / name

    @property
    def has_environment(self) -> bool:
        return self.environment is not None

    def unit(self, file: int, drop_invalid: bool = False) -> Scene:
        """The SOG unit ``file`` (an index into :attr:`filenames`), decoded whole."""
        return sog.read(self.unit_path(self.filenames[file], "filenames"), drop_invalid)

    def rows_of(self, unit: Scene, index: int, level: int) -> Scene:
        """Chunk ``index``'s splats of ``level`` out of its decoded ``unit``."""
        file, offset, count = self.chunks[index].lods[level]
        if offset + count > unit.count:
            raise SceneFormatError(self.path, f"chunk {index} level {level} needs rows "
                                              f"{offset}-{offset + count - 1} of "
                                              f"{self.filenames[file]}, which holds "
                                              f"{unit.count}", "tree")
        return unit.subset(np.arange(offset, offset + count))

    def load(self, level: int = 0, chunks=None, drop_invalid: bool = False,
             environment: bool = True) -> Scene:
        """The splats of ``level`` in the ``chunks`` (indices into :attr:`chunks`; default all),
        in chunk order, followed by the environment's when ``environment`` (and there is one)."""
        if not 0 <= level < self.levels:
            raise SceneFormatError(self.path, f"level {level} does not exist (levels 0-"
                                              f"{self.levels - 1})", "lodLevels")
        picked = range(len(self.chunks)) if chunks is None else chunks
        units: dict[int, Scene] = {}
        parts = []
        for index in picked:
            ref = self.chunks[index].lods.get(level)
            if ref is None or ref[2] == 0:
                continue
            if ref[0] not in units:
                units[ref[0]] = self.unit(ref[0], drop_invalid)
            parts.append(self.rows_of(units[ref[0]], index, level))
        if environment and self.environment is not None:
            parts.append(sog.read(self.unit_path(self.environment, "environment"), drop_invalid))
        if not parts:
            raise SceneFormatError(self.path, f"level {level} holds no splats", "tree")
        return concatenate(parts)


def concatenate(parts: list[Scene]) -> Scene:
    """One scene of ``parts`` in order (SH padded with zeros to the highest degree)."""
    if len(parts) == 1:
        return parts[0]
    width = max(p.sh.shape[1] for p in parts)

    def sh(p: Scene) -> np.ndarray:
        if p.sh.shape[1] == width:
            return p.sh
        return np.concatenate([p.sh, np.zeros((p.count, width - p.sh.shape[1], 3), p.sh.dtype)], 1)

    return Scene(np.concatenate([p.means for p in parts]), np.concatenate([p.quats for p in parts]),
                 np.concatenate([p.log_scales for p in parts]),
                 np.concatenate([p.opacity_logits for p in parts]),
                 np.concatenate([sh(p) for p in parts]), parts[0].kind)


def _int(path, value, field: str, low: int = 0) -> int:
    if not isinstance(value, int) or isinstance(value, bool) or value < low:
        raise SceneFormatError(path, f"{value!r} is not an integer >= {low}", field)
    return value


def _box(path, node: dict, field: str) -> tuple[np.ndarray, np.ndarray]:
    bound = node.get("bound")
    try:
        lo = np.asarray(bound["min"], np.float64)
        hi = np.asarray(bound["max"], np.float64)
    except (TypeError, KeyError, ValueError):
        raise SceneFormatError(path, "expected {\"min\": [x, y, z], \"max\": [x, y, z]}",
                               f"{field}.bound") from None
    if lo.shape != (3,) or hi.shape != (3,) or not (np.isfinite(lo).all() and np.isfinite(hi).all()):
        raise SceneFormatError(path, "expected three finite numbers in min and max",
                               f"{field}.bound")
    return lo, hi


def _leaf(path, node: dict, field: str, levels: int, files: int) -> Chunk:
    lo, hi = _box(path, node, field)
    lods = {}
    raw = node.get("lods", {})
    if not isinstance(raw, dict):
        raise SceneFormatError(path, "expected an object of levels", f"{field}.lods")
    for key, ref in raw.items():
        where = f"{field}.lods.{key}"
        if not key.isdigit() or int(key) >= levels:
            raise SceneFormatError(path, f"level {key!r} is not one of 0-{levels - 1}", where)
        if not isinstance(ref, dict):
            raise SceneFormatError(path, "expected {file, offset, count}", where)
        file = _int(path, ref.get("file"), f"{where}.file")
        if file >= files:
            raise SceneFormatError(path, f"file {file} is not one of the {files} filenames",
                                   f"{where}.file")
        lods[int(key)] = (file, _int(path, ref.get("offset"), f"{where}.offset"),
                          _int(path, ref.get("count"), f"{where}.count"))
    errors = node.get("errors")
    if errors is not None:
        if (not isinstance(errors, list) or len(errors) != levels or not all(
                isinstance(e, (int, float)) and not isinstance(e, bool) and np.isfinite(e) and e >= 0
                for e in errors)):
            raise SceneFormatError(path, f"expected {levels} finite numbers >= 0", f"{field}.errors")
        errors = tuple(float(e) for e in errors)
    return Chunk(lo, hi, lods, errors)


def _walk(path, node, field: str, levels: int, files: int, out: list, depth: int = 0) -> None:
    if not isinstance(node, dict):
        raise SceneFormatError(path, "expected a tree node (an object)", field)
    if depth > MAX_DEPTH:
        raise SceneFormatError(path, f"the tree is deeper than {MAX_DEPTH}", field)
    children = node.get("children")
    if children is None:
        out.append(_leaf(path, node, field, levels, files))
        return
    if not isinstance(children, list) or not children:
        raise SceneFormatError(path, "expected a list of nodes", f"{field}.children")
    for i, child in enumerate(children):
        _walk(path, child, f"{field}.children[{i}]" if depth < 3 else "tree", levels, files, out,
              depth + 1)


def read_structure(path: str | Path) -> StreamedSog:
    """The manifest at ``path`` (levels, per-level counts, chunks with bounds), checked whole;
    no splat is read."""
    path = Path(path)
    meta = _binary.json_object(path, "lod-meta.json")
    if meta.get("version") not in VERSIONS:
        raise SceneFormatError(path, f"Streamed SOG version {meta.get('version')!r} is not "
                                     "supported (supported: 1, or none)", "version")
    levels = _int(path, meta.get("lodLevels"), "lodLevels", 1)
    names = meta.get("filenames")
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise SceneFormatError(path, "expected a list of file names", "filenames")
    env = meta.get("environment")
    if env is not None and not isinstance(env, str):
        raise SceneFormatError(path, "expected a file name", "environment")
    chunks: list[Chunk] = []
    _walk(path, meta.get("tree"), "tree", levels, len(names), chunks)
    found = [sum(c.count(level) for c in chunks) for level in range(levels)]
    counts = meta.get("counts")
    if counts is not None and counts != found:
        raise SceneFormatError(path, f"counts {counts!r} disagree with the tree's {found}", "counts")
    return StreamedSog(path, levels, tuple(found), tuple(names), tuple(chunks), env,
                       manifest_box(meta))


def read(path: Path, drop_invalid: bool = False, level: int = 0) -> Scene:
    """The splats of ``level`` (default 0, the finest) of the Streamed SOG at ``path``, with its
    environment."""
    return read_structure(path).load(level, drop_invalid=drop_invalid)


def stored_bytes(path: Path) -> int:
    """Bytes of the manifest and every unit it names."""
    lod = read_structure(path)
    names = [*lod.filenames, *([lod.environment] if lod.environment else [])]
    return Path(path).stat().st_size + sum(
        sog.stored_bytes(lod.unit_path(n, "filenames")) for n in names
        if lod.unit_path(n, "filenames").is_file())


def level_info(path: Path) -> dict:
    """What ``splatgl info`` says of the levels: splats per level, chunks, the level loaded."""
    lod = read_structure(path)
    return {"counts": list(lod.counts), "chunks": len(lod.chunks), "loaded": 0}
