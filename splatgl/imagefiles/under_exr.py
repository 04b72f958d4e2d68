"""``--under`` geometry files: an EXR of opaque geometry rendered from the same camera, read
into :class:`splatgl.output.under.UnderImage` (:func:`read_under`) and written
(:func:`write_under`, what the project's mesh rasterizer makes for tests and demos).

The file holds colour (R, G, B; premultiplied by A where it has an A channel, else opaque) and
a depth channel (Z by default): the geometry's view-space z, or its distance along each pixel's
ray, as the file's ``splatgl:depth`` attribute (``z`` or ``distance``) or the caller says.  A
pixel without geometry has a depth of 0 or +inf (as renderers write for their background); a
NaN or negative depth, or colour that is not finite, is refused in one line (the count and the
first such pixel).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from ..errors import SplatglError
from ..output.under import DepthKind, UnderImage
from .images import write_image

#: The EXR header attribute that says what the depth channel holds.
DEPTH_ATTRIBUTE = "splatgl:depth"


def write_under(path: str | Path, rgba: np.ndarray, depth: np.ndarray,
                kind: DepthKind = DepthKind.Z) -> None:
    """An EXR of R, G, B, A (``rgba`` (H, W, 4)) and Z (``depth`` (H, W) in ``kind``; 0 where
    it is not finite, i.e. no geometry) with the ``splatgl:depth`` attribute: what ``splatgl
    render --under`` reads."""
    write_image(path, rgba, depth=np.where(np.isfinite(depth), depth, 0.0),
                attributes={DEPTH_ATTRIBUTE: DepthKind(kind).value})


def _channel(names: list[str], wanted: str) -> int | None:
    return names.index(wanted) if wanted in names else None


def read_under(path: str | Path, kind: DepthKind | str | None = None,
               channel: str = "Z") -> UnderImage:
    """Read the geometry in ``path`` (an EXR with R, G, B, optionally A, and ``channel``).

    ``kind`` says what the depth channel holds; None takes the file's ``splatgl:depth``
    attribute.  Refused in one line naming the file: not an EXR, a missing channel, no
    statement of the depth kind (or one contradicting ``kind``), no geometry pixel at all.
    """
    path = Path(path)
    if path.suffix.lower() != ".exr":
        raise SplatglError(f"--under {path}: give an EXR file (colour and a depth channel)")
    if not path.is_file():
        raise SplatglError(f"--under {path}: no such file")
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise SplatglError(f"--under {path}: not a readable image ({' '.join(oiio.geterror().split())})")
    try:
        spec = inp.spec()
        names = list(spec.channelnames)
        stated = spec.getattribute(DEPTH_ATTRIBUTE)
        pixels = inp.read_image(oiio.FLOAT)
    finally:
        inp.close()
    if pixels is None:
        raise SplatglError(f"--under {path}: the file's pixels cannot be read")
    pixels = np.asarray(pixels, np.float32).reshape(spec.height, spec.width, spec.nchannels)
    missing = [c for c in ("R", "G", "B", channel) if c not in names]
    if missing:
        raise SplatglError(f"--under {path}: no channel {', '.join(missing)} (the file has "
                           f"{', '.join(names)})")
    kind = _depth_kind(path, kind, stated)
    rgb = pixels[..., [names.index(c) for c in ("R", "G", "B")]]
    a = _channel(names, "A")
    alpha = pixels[..., a] if a is not None else np.ones(pixels.shape[:2], np.float32)
    depth = pixels[..., names.index(channel)]
    _check_values(path, names, pixels, channel)
    depth = np.where(depth > 0, depth, np.inf).astype(np.float32)   # 0 and +inf: background
    if not np.isfinite(depth).any():
        raise SplatglError(f"--under {path}: channel {channel} holds no geometry (no finite "
                           "positive depth)")
    return UnderImage(np.ascontiguousarray(rgb), np.ascontiguousarray(alpha), depth, kind, path)


def _check_values(path: Path, names: list[str], pixels: np.ndarray, channel: str) -> None:
    """Refuse (one line: the count and the first pixel) a depth that is NaN or negative
    (-inf included): 0 and +inf mean no geometry, any other depth must be positive; and
    colour or alpha that is not finite."""
    depth = pixels[..., names.index(channel)]
    bad = np.isnan(depth) | (depth < 0)
    what = "NaN or negative (a depth is positive; 0 or inf where there is no geometry)"
    if not bad.any():
        plane = [c for c in ("R", "G", "B", "A") if c in names]
        values = pixels[..., [names.index(c) for c in plane]]
        bad = ~np.isfinite(values).all(-1)
        channel, depth, what = "/".join(plane), values, "not finite"
    if bad.any():
        y, x = (int(v) for v in np.argwhere(bad)[0])
        raise SplatglError(f"--under {path}: channel {channel} is {what} at {int(bad.sum())} "
                           f"pixel{'s' if bad.sum() != 1 else ''} (the first at x={x}, y={y}: "
                           f"{', '.join(f'{v:g}' for v in np.atleast_1d(depth[y, x]))})")


def _depth_kind(path: Path, kind, stated) -> DepthKind:
    """The depth kind given or stated in the file; both must agree, one must say it."""
    choices = " or ".join(k.value for k in DepthKind)
    if stated is not None and str(stated) not in {k.value for k in DepthKind}:
        raise SplatglError(f"--under {path}: attribute {DEPTH_ATTRIBUTE} is {stated!r}, not {choices}")
    stated = DepthKind(str(stated)) if stated is not None else None
    given = DepthKind(kind) if kind is not None else None
    if given is not None and stated is not None and given is not stated:
        raise SplatglError(f"--under {path}: the file says its depth is {stated.value} "
                           f"({DEPTH_ATTRIBUTE}), --under-depth says {given.value}")
    if given is None and stated is None:
        raise SplatglError(f"--under {path}: the file does not say whether its depth is view-space "
                           f"z or distance along the ray; give --under-depth {choices}")
    return given or stated
