"""Scene-file tags that say how a scene was trained, read from headers only.

:func:`antialias_tag` tells whether a file marks its scene as trained with antialiasing
(mip-splatting's 2D filter, which the renderer's ``--antialias`` compensation matches):

- SPZ: header flags bit 0 ("antialiased"; gzip bodies are inflated just enough for the header);
- PLY and compressed PLY: a ``comment SplatRenderMode: mip`` line (Brush, splat-transform) or
  ``comment antialiased 1`` (Postshot), or a ``filter_3D`` vertex property (mip-splatting's
  unfused export, whose 3D filter is then not applied here);
- SOG: ``"model": "antialiased"`` in meta.json.

Untagged files (and formats without such a tag: .splat, .ksplat, glTF) give None.
"""

from __future__ import annotations

import zlib
from pathlib import Path

from ..errors import SceneFormatError

#: Bytes read from the start of a file to find a tag.
HEAD_BYTES = 1 << 16


def antialias_tag(path: str | Path) -> str | None:
    """A short description of the antialiasing tag ``path`` carries, or None."""
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            head = fh.read(HEAD_BYTES)
    except OSError:
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
