"""Image output through OpenImageIO, in the formats of :mod:`splatgl.imagefiles.image_formats`:
PNG and TIFF (8 or 16 bit, RGB), EXR (float RGBA, and Z with the depth layer).

Every file is written atomically (:func:`splatgl.writing.atomic.atomic_target`): checked
(:func:`image_file_problem`: the header's size, channels and type, and the end of the data
really there) before it is renamed, so a failed or short write (a full disk) raises one line
naming the target and leaves nothing behind.
"""

from __future__ import annotations

import os
import sys
import tempfile
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from ..writing.atomic import atomic_target, cannot_write
from .image_formats import BIT_DEPTHS, image_format
from ..output.layers import Layer, with_layers
from ..errors import SplatglError

#: The last 12 bytes of every complete PNG file: the IEND chunk (length 0, type, CRC).
_PNG_END = b"\x00\x00\x00\x00IEND\xaeB`\x82"


def check_image_suffix(path: str | Path, what: str = "") -> None:
    """Refuse a file name :func:`write_image` cannot write (before any work); ``what`` (an
    option name) starts the message (:func:`splatgl.imagefiles.image_formats.image_format`)."""
    image_format(path, what)


@dataclass(frozen=True)
class ImageFileInfo:
    """What a complete image file holds: size, channels, bits per channel (None: float)."""

    width: int
    height: int
    channels: int
    bits: int | None
    #: The header's ``ImageDescription`` (``render --path`` frames: what made them,
    #: :mod:`splatgl.imagefiles.frame_record`), None where it has none.
    description: str | None = None

    def mismatch(self, width: int | None = None, height: int | None = None,
                 channels: int | None = None, bit_depth: int | None = None) -> str | None:
        """How this file differs from what was asked (None: it does not)."""
        if width is not None and height is not None and (self.width, self.height) != (width, height):
            return f"it is {self.width}x{self.height}, not {width}x{height}"
        if channels is not None and self.channels != channels:
            return f"it has {self.channels} channels, not {channels}"
        if bit_depth is not None and self.bits is not None and self.bits != bit_depth:
            return f"it has {self.bits} bits per channel, not {bit_depth}"
        return None


#: The lines C libraries under OpenImageIO print on standard error themselves (libpng's
#: default handlers), whose reason OpenImageIO also returns, for splatgl's one line.
LIBRARY_LINES = ("libpng error:", "libpng warning:")


@contextmanager
def quiet_image_library():
    """Keep the image libraries' own ``libpng error: ...`` lines (:data:`LIBRARY_LINES`) off
    standard error while OpenImageIO reads a file: their reason comes back through
    ``geterror()`` into splatgl's one-line message.  Standard error (file descriptor 2) goes to
    a temporary file meanwhile; any other line written there is passed on afterwards."""
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError):      # no file descriptor 2 to redirect
        yield
        return
    with tempfile.TemporaryFile() as caught:
        os.dup2(caught.fileno(), 2)
        try:
            yield
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            caught.seek(0)
            lines = caught.read().decode("utf-8", "replace").splitlines(keepends=True)
            kept = "".join(line for line in lines if not line.startswith(LIBRARY_LINES))
            if kept:
                os.write(2, kept.encode("utf-8"))


def inspect_image(path: str | Path) -> ImageFileInfo | str:
    """The header of a complete image file, or why the file is not one (a string).

    Cheap enough to run on every frame: reads the header and the end of the data, not the
    pixels (PNG: the file must end with its IEND chunk; TIFF/EXR: the last scanline must
    decode), so a file cut short by a full disk or a killed writer is found.
    """
    path = Path(path)
    try:
        size = path.stat().st_size
        if size == 0:
            return "the file is empty"
        if path.suffix.lower() == ".png":
            with open(path, "rb") as fh:
                fh.seek(max(size - len(_PNG_END), 0))
                if fh.read() != _PNG_END:
                    return f"the file is cut short ({size} bytes, no PNG end chunk)"
    except OSError as exc:
        return f"cannot read it ({exc.strerror})"
    with quiet_image_library():
        inp = oiio.ImageInput.open(str(path))
    if inp is None:
        return f"not a readable image ({' '.join(oiio.geterror().split())})"
    try:
        spec = inp.spec()
        with quiet_image_library():
            last = inp.read_scanline(spec.height - 1, 0, oiio.FLOAT) if path.suffix.lower() != ".png" else 0
        if last is None:
            return f"the file is cut short ({size} bytes: {' '.join(inp.geterror().split())})"
        bits = {"uint8": 8, "uint16": 16}.get(str(spec.format))
        description = spec.getattribute("ImageDescription")
        return ImageFileInfo(spec.width, spec.height, spec.nchannels, bits,
                             description if isinstance(description, str) else None)
    finally:
        inp.close()


def image_file_problem(path: str | Path, width: int | None = None, height: int | None = None,
                       channels: int | None = None, bit_depth: int | None = None) -> str | None:
    """Why ``path`` is not a complete image (:func:`inspect_image`) of the given size, channel
    count and (PNG/TIFF) bits per channel, or None when it is one."""
    info = inspect_image(path)
    return info if isinstance(info, str) else info.mismatch(width, height, channels, bit_depth)


def _clean(message: str) -> str:
    """An OpenImageIO message on one line."""
    return " ".join(message.split()) or "no reason given"


def write_image(path: str | Path, rgba: np.ndarray, bit_depth: int = 8,
                depth: np.ndarray | None = None,
                extra: dict[str, np.ndarray] | None = None,
                attributes: dict[str, str] | None = None) -> None:
    """Write an (H, W, 4) float32 image (row 0 at the top), atomically.

    What the file holds follows its format (:mod:`splatgl.imagefiles.image_formats`): PNG/TIFF get
    RGB (the background already composited), clipped to [0, 1] and quantised once to
    ``bit_depth`` (8 or 16).  EXR gets float32 R, G, B, A (A = accumulated alpha), when
    ``depth`` (H, W) is given a Z channel (the expected depth, 0 where nothing was drawn), and
    the (H, W) planes of ``extra`` as float32 channels of those names, in that order (the
    further layers, :func:`splatgl.imagefiles.layer_files.exr_channels`); ``attributes`` become
    string attributes of the header (EXR: what the channels mean, ``splatgl:depth``; any
    format: a path frame's ``ImageDescription``, :mod:`splatgl.imagefiles.frame_record`).
    """
    path = Path(path)
    fmt = image_format(path)
    if bit_depth not in BIT_DEPTHS:
        raise SplatglError(f"bit depth must be {' or '.join(map(str, BIT_DEPTHS))}, got {bit_depth}")
    layers = with_layers(Layer.DEPTH) if depth is not None else with_layers()
    channels = fmt.channels(layers)
    if fmt.is_float:
        planes = [rgba[..., :4]] + ([depth[..., None]] if "Z" in channels else [])
        extra = extra or {}
        planes += [np.asarray(plane)[..., None] for plane in extra.values()]
        channels = channels + tuple(extra)
        pixels, pixel_type = np.ascontiguousarray(np.concatenate(planes, -1), np.float32), oiio.FLOAT
    else:
        scale = 255.0 if bit_depth == 8 else 65535.0
        dtype = np.uint8 if bit_depth == 8 else np.uint16
        q = np.clip(rgba[..., :3], 0.0, 1.0) * scale + 0.5
        pixels = np.ascontiguousarray(q.astype(dtype))
        pixel_type = oiio.UINT8 if bit_depth == 8 else oiio.UINT16
    h, w = pixels.shape[:2]
    spec = oiio.ImageSpec(w, h, len(channels), pixel_type)
    spec.channelnames = channels
    for name, value in (attributes or {}).items():
        spec.attribute(name, str(value))

    def complete(tmp: Path) -> str | None:
        return image_file_problem(tmp, w, h, len(channels), None if fmt.is_float else bit_depth)

    with atomic_target(path, complete) as tmp:
        out = oiio.ImageOutput.create(str(tmp))
        if out is None:
            raise SplatglError(f"{path}: OpenImageIO cannot write this format ({_clean(oiio.geterror())})")
        try:
            ok = out.open(str(tmp), spec) and out.write_image(pixels)
            problem = None if ok else out.geterror()
        finally:
            closed = out.close()
        if problem is None and not closed:
            problem = out.geterror()
        if problem is not None:
            raise cannot_write(path, _clean(problem).rstrip("."))


def read_image(path: str | Path) -> np.ndarray:
    """(H, W, C) float32 pixels of an image file as stored (integer formats scaled to [0, 1]):
    a PNG's colour with its straight alpha is not multiplied by that alpha (OpenImageIO's
    default for such files; ``eval`` then composited a photograph's alpha twice)."""
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    with quiet_image_library():
        inp = oiio.ImageInput.open(str(path), config)
    if inp is None:
        raise SplatglError(f"{path}: cannot read image ({_clean(oiio.geterror())})")
    try:
        with quiet_image_library():
            pixels = inp.read_image(oiio.FLOAT)
        if pixels is None:
            raise SplatglError(f"{path}: cannot read its pixels ({_clean(inp.geterror())})")
        return np.asarray(pixels, np.float32)
    finally:
        inp.close()
