"""The ``.lod.ply`` file: an INRIA PLY whose ``vertex`` element holds the leaves (the original
splats in Morton order, so any PLY reader renders the full-detail scene) followed by an element
``lod_node`` with the merged parents, level by level, in the same properties; a header comment
``lod branching B`` gives the tree's shape (:func:`splatgl.lod.build.level_offsets`)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..errors import SceneFormatError
from ..formats import ply, ply_write
from ..formats.metadata import apply_framing_box, box_comment
from ..formats.written import write_checked
from ..scene.splats import Scene, activate
from .build import LodTree, bounding_radii, level_offsets

ELEMENT = "lod_node"
#: The element after ``lod_node`` with every node's bounding sphere (``x y z radius``, float32,
#: leaves first, in node order): what a cut reads (:mod:`splatgl.lod.lazy`).  Files written
#: before it are still read (the radii recomputed).
BOUNDS = "lod_bound"
#: A level-of-detail file's name ends so (any ``.ply`` is read, but not ``.compressed.ply``).
SUFFIX = ".lod.ply"
_BRANCHING = re.compile(rb"^comment lod branching (\d+)\s*$", re.M)
#: The header comment with the anchor (:func:`COMMENTS`).
ANCHOR_COMMENT = re.compile(rb"^comment lod anchor (\S+) (\S+) (\S+)\s*$", re.M)


def stored_branching(path: Path, head: bytes) -> int:
    """The branching a ``.lod.ply`` header (bytes) of the file ``path`` records; one line
    naming the file where it records none."""
    match = _BRANCHING.search(head)
    if match is None:
        raise SceneFormatError(path, "not a splatgl LOD file (no 'comment lod branching B' "
                                     "line); build one with 'splatgl lod'", ELEMENT)
    return int(match.group(1))


def stored_anchor(head: bytes) -> np.ndarray | None:
    """(3,) float64 anchor a ``.lod.ply`` header (bytes) stores, or None (written before it)."""
    match = ANCHOR_COMMENT.search(head)
    if match is None:
        return None
    anchor = np.array([float(v) for v in match.groups()])
    anchor.flags.writeable = False
    return anchor


def check_lod_name(path: Path) -> None:
    """Refuse an output name that says another format (``out.png`` would hold a PLY)."""
    name = Path(path).name.lower()
    if not name.endswith(".ply") or name.endswith(".compressed.ply"):
        raise SceneFormatError(path, f"a level-of-detail file is an INRIA PLY; name it *{SUFFIX}")


def COMMENTS(branching: int, lo: np.ndarray, hi: np.ndarray) -> tuple[str, ...]:  # noqa: N802
    """The header comments: who wrote it, the tree's shape, the anchor the lazy reader's cut
    subtracts (:func:`anchor_of` the box) and the leaves' 1-99 % box ``(lo, hi)``, which frames
    the file read whole or streamed alike
    (:func:`splatgl.formats.metadata.apply_framing_box`)."""
    xyz = " ".join(repr(float(v)) for v in anchor_of(lo, hi))
    return ("written by splatgl lod", f"lod branching {branching}", f"lod anchor {xyz}",
            box_comment(lo, hi))


def leaf_box(means: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(lo, hi)`` float64 (3,): the 1-99 % box of the leaves' (N, 3) ``means``, taken in
    float64: the one both writers store (the out-of-core build finds the same box in its
    streaming passes, :class:`splatgl.lod.ply_rows.BoxFinder`)."""
    points = means.astype(np.float64)
    return np.percentile(points, 1.0, axis=0), np.percentile(points, 99.0, axis=0)


def anchor_of(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(3,) float64 centre of the box ``(lo, hi)`` (a float32 value; zeros where not finite)."""
    anchor = (0.5 * (np.asarray(lo) + np.asarray(hi))).astype(np.float32).astype(np.float64)
    return anchor if np.isfinite(anchor).all() else np.zeros(3)


def bounds_rows(means: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """The :data:`BOUNDS` rows of nodes with float32 ``means`` (K, 3) and ``radius`` (K,)."""
    out = np.empty(means.shape[0], [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("radius", "<f4")])
    for i, c in enumerate("xyz"):
        out[c] = means[:, i]
    out["radius"] = radius
    return out


def write_lod(path: Path, tree: LodTree) -> None:
    """Write ``tree`` (atomically: a temp file, checked to be complete, then renamed; a failed
    write raises one line naming ``path``) to a ``*.ply`` name (:func:`check_lod_name`)."""
    path = Path(path)
    check_lod_name(path)
    n = tree.level_size(0)
    leaves = tree.nodes.subset(slice(0, n))
    inner = tree.nodes.subset(slice(n, None))
    write_checked(path, lambda tmp: ply_write.write_elements(
        tmp, [("vertex", ply_write.scene_to_vertices(leaves, normals=False)),
              (ELEMENT, ply_write.scene_to_vertices(inner, normals=False)),
              (BOUNDS, bounds_rows(tree.nodes.means, tree.radius))],
        comments=COMMENTS(tree.branching, *leaf_box(leaves.means))))


def is_lod_file(path: Path) -> bool:
    """Whether ``path``'s PLY header declares the lod_node element."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(1 << 16)
    except OSError:
        return False
    return head.startswith(b"ply") and f"element {ELEMENT} ".encode() in head.split(b"end_header")[0]


def level_info(path: Path) -> dict:
    """What ``splatgl info`` says of a ``.lod.ply``'s levels, from its header alone: nodes per
    level, finest first, the branching, and the level a reader loads (0, the leaves)."""
    path = Path(path)
    with open(path, "rb") as fh:
        header = ply.parse_header(path, fh)
        fh.seek(0)
        branching = stored_branching(path, fh.read(header.body_offset))
    leaves = sum(e.count for e in header.elements if e.name == "vertex")
    offsets = level_offsets(leaves, branching)
    return {"counts": [int(b - a) for a, b in zip(offsets[:-1], offsets[1:])],
            "branching": branching, "loaded": 0}


def levels_of(path) -> dict | None:
    """The levels a level-of-detail file holds (``{"counts": splats per level, finest first,
    ...}``, as ``splatgl info`` shows them), from its header or manifest alone: a ``.lod.ply``
    (:func:`level_info`), a Streamed SOG or an LCC scene (their format's ``level_info``); None
    for any other file."""
    from ..formats import detect_format

    info = getattr(detect_format(Path(path)), "level_info", None)
    if info is None and is_lod_file(Path(path)):
        info = level_info
    return None if info is None else info(Path(path))


def dropped_levels_note(path) -> str | None:
    """The note for a command that reads ``path`` whole and writes a plain scene (``convert``,
    ``edit``): only its finest level is read, its coarser ones are not written; None where it
    holds one level."""
    levels = levels_of(path)
    counts = [] if levels is None else levels["counts"]
    if len(counts) < 2:
        return None
    coarser = len(counts) - 1
    return (f"{path} is a level-of-detail file: its finest level ({counts[0]:,} splats) is "
            f"read; its {coarser} coarser level{'s' if coarser != 1 else ''} "
            f"({sum(counts[1:]):,} splats) {'are' if coarser != 1 else 'is'} not written "
            "(build them again with 'splatgl lod' on the output)")


def framed_leaves(tree: LodTree, path: Path) -> Scene:
    """The leaves of ``tree`` (read from ``path``) as a scene, framed as
    :func:`splatgl.formats.load_scene` frames the file (its recorded box): what the default
    camera and orbits of an in-memory level of detail frame."""
    return apply_framing_box(tree.nodes.subset(slice(0, tree.level_size(0))), path)


def read_lod(path: Path, progress=None) -> LodTree:
    """Read a ``.lod.ply`` back into a :class:`LodTree` (radii recomputed from the nodes), its
    nodes anchored where the file says (:func:`stored_anchor`)."""
    path = Path(path)
    leaves = ply.read(path, progress=progress)
    with open(path, "rb") as fh:
        header = ply.parse_header(path, fh)
        fh.seek(0)
        head = fh.read(header.body_offset)
        branching = stored_branching(path, head)
        offset = header.body_offset
        elem = None
        for e in header.elements:
            if e.name == ELEMENT:
                elem = e
                break
            offset += e.count * e.dtype(header.order).itemsize
        if elem is None or header.order is None:
            raise SceneFormatError(path, f"no binary '{ELEMENT}' element", ELEMENT)
        offsets = level_offsets(leaves.count, branching)
        if elem.count != offsets[-1] - leaves.count:
            raise SceneFormatError(path, f"{elem.count} nodes, expected "
                                         f"{offsets[-1] - leaves.count} for {leaves.count} leaves "
                                         f"and branching {branching}", ELEMENT)
        dtype = elem.dtype(header.order)
        fh.seek(offset)
        rows = np.fromfile(fh, dtype, elem.count)
        if rows.size != elem.count:
            raise SceneFormatError(path, "file is truncated inside the lod_node element", ELEMENT)
    cols = ply._Columns(path, [n for n, _ in elem.properties], elem.count)
    cols.fill(rows, 0)
    inner = activate(path, cols.means, cols.quats, cols.log_scales, cols.opacity, cols.sh)
    nodes = Scene(np.concatenate([leaves.means, inner.means]),
                  np.concatenate([leaves.quats, inner.quats]),
                  np.concatenate([leaves.log_scales, inner.log_scales]),
                  np.concatenate([leaves.opacity_logits, inner.opacity_logits]),
                  np.concatenate([leaves.sh, inner.sh]), leaves.kind)
    anchor = stored_anchor(head)
    if anchor is not None:   # the anchor the lazy reader's cut and streamed frames use, so an
        nodes.__dict__["anchor"] = anchor   # in-memory frame of this file is their frame
    return LodTree(nodes, offsets, branching, np.arange(leaves.count),
                   bounding_radii(nodes, offsets, branching))
