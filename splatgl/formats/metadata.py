"""Scene-file tags that say how a scene was trained, read from headers only.

:func:`antialias_tag` tells whether a file marks its scene as trained with antialiasing
(mip-splatting's 2D filter, which the renderer's ``--antialias`` compensation matches):

- SPZ: header flags bit 0 ("antialiased"; gzip bodies are inflated just enough for the header);
- PLY and compressed PLY: a ``comment SplatRenderMode: mip`` line (Brush, splat-transform) or
  ``comment antialiased 1`` (Postshot), or a ``filter_3D`` vertex property (mip-splatting's
  unfused export, whose 3D filter is then not applied here);
- SOG: ``"model": "antialiased"`` in meta.json.

Untagged files (and formats without such a tag: .splat, .ksplat, glTF) give None.

:func:`framing_box` reads the box a level-of-detail file records for framing, which ``splatgl
lod`` writes (the 1-99 % box of the leaves' centres): a ``.lod.ply`` header's ``comment lod
box``, a Streamed SOG manifest's ``splatglFramingBox``; so that the file is framed alike
whether it is read whole or streamed (:func:`apply_framing_box`).
"""

from __future__ import annotations

import re
import zlib
from pathlib import Path

import numpy as np

from ..errors import SceneFormatError

#: Bytes read from the start of a file to find a tag.
HEAD_BYTES = 1 << 16
#: The header comment with the framing box: ``lo`` then ``hi``, x y z each, as Python writes a
#: float64 (``repr``).
BOX_COMMENT = re.compile(rb"^comment lod box" + rb" (\S+)" * 6 + rb"\s*$", re.M)
#: The Streamed SOG manifest key holding the same box, ``[x0, y0, z0, x1, y1, z1]``
#: (:mod:`splatgl.formats.streamed_sog`; other readers ignore it).
BOX_KEY = "splatglFramingBox"


def box_comment(lo: np.ndarray, hi: np.ndarray) -> str:
    """The header comment (without ``comment``) recording the framing box ``(lo, hi)``."""
    return "lod box " + " ".join(repr(float(v)) for v in (*lo, *hi))


def checked_box(values) -> tuple[np.ndarray, np.ndarray] | None:
    """``(lo, hi)`` float64 (3,) of six numbers ``x0 y0 z0 x1 y1 z1``, or None where they are
    not six finite numbers with ``lo <= hi`` (a malformed box is ignored, not refused)."""
    try:
        arr = np.array([float(v) for v in values], np.float64)
    except (TypeError, ValueError):
        return None
    if arr.shape != (6,):
        return None
    lo, hi = arr[:3], arr[3:]
    if not (np.isfinite(arr).all() and (lo <= hi).all()):
        return None
    lo.flags.writeable = hi.flags.writeable = False
    return lo, hi


def header_box(head: bytes) -> tuple[np.ndarray, np.ndarray] | None:
    """``(lo, hi)`` float64 (3,) of the framing box a PLY header (bytes) records, or None
    (none recorded, or not finite and ordered)."""
    match = BOX_COMMENT.search(head.split(b"end_header", 1)[0])
    return None if match is None else checked_box(match.groups())


def _head(path: str | Path) -> bytes | None:
    """The first :data:`HEAD_BYTES` of ``path``, or None where it cannot be read."""
    try:
        with open(path, "rb") as fh:
            return fh.read(HEAD_BYTES)
    except OSError:
        return None


def framing_box(path: str | Path) -> tuple[np.ndarray, np.ndarray] | None:
    """The framing box ``path`` records, or None: a PLY header's (:func:`header_box`), or a
    Streamed SOG manifest's (:func:`manifest_box`)."""
    head = _head(path)
    if head is None:
        return None
    if head.startswith(b"ply"):
        return header_box(head)
    if not (head.lstrip().startswith(b"{") and b'"lodLevels"' in head):
        return None   # not a Streamed SOG manifest (a glTF is parsed no second time)
    from ._binary import json_object

    try:
        return manifest_box(json_object(Path(path), "lod-meta.json"))
    except (SceneFormatError, OSError):
        return None


def manifest_box(meta: dict) -> tuple[np.ndarray, np.ndarray] | None:
    """The framing box a Streamed SOG manifest (parsed JSON) records under :data:`BOX_KEY`, or
    None (none, or malformed)."""
    box = meta.get(BOX_KEY)
    return checked_box(box) if isinstance(box, list) else None


def apply_framing_box(scene, path: str | Path):
    """``scene`` (read from ``path``, whole) framed by the box ``path`` records, where it
    records one (:func:`framing_box`): its ``robust_bounds``, which the default camera, orbits,
    the viewer and the anchor read, become that box.  A level-of-detail file streamed under
    ``--memory`` frames the same box without reading its leaves
    (:func:`splatgl.lod.stream_frames.framing_scene`,
    :func:`splatgl.lod.stream_levels.framing_of`), so the two give the same default view, and
    the source scene's (up to the float32 rounding of its own percentiles)."""
    box = framing_box(path)
    if box is not None and scene.count:
        scene.__dict__["robust_bounds"] = box
    return scene


def antialias_tag(path: str | Path) -> str | None:
    """A short description of the antialiasing tag ``path`` carries, or None."""
    path = Path(path)
    head = _head(path)
    if head is None:
        return None
    if head.startswith(b"\x1f\x8b"):
        try:
            head = zlib.decompressobj(wbits=31).decompress(head, 16)
        except zlib.error:
            return None
    if head.startswith(b"NGSP") and len(head) >= 15:
        return "SPZ header flag 'antialiased'" if head[14] & 1 else None
    if head.startswith(b"ply"):
        header = head.split(b"end_header", 1)[0].decode("ascii", "replace")
        for line in header.replace("\r\n", "\n").split("\n"):
            words = line.split()
            if words[:2] == ["comment", "SplatRenderMode:"] and words[2:3] == ["mip"]:
                return "PLY comment 'SplatRenderMode: mip'"
            if words[:3] == ["comment", "antialiased", "1"]:
                return "PLY comment 'antialiased 1'"
            if words[:1] == ["property"] and words[-1:] == ["filter_3D"]:
                return "PLY property 'filter_3D' (mip-splatting)"
        return None
    from . import sog
    if sog.sniff(head):
        try:
            model = sog.read_meta(path).get("model")
        except SceneFormatError:
            return None
        return "SOG meta.json model 'antialiased'" if model == "antialiased" else None
    return None
