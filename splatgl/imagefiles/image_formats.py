"""The image formats splatgl writes, in one table that every check, writer and command option
reads: a new format is one row here (and its writer in :mod:`splatgl.imagefiles.images`).

Each format says what a file of it holds: integer formats (PNG, TIFF) the colour with the
background composited, quantised to 8 or 16 bits; float formats (EXR) float32 colour, alpha, the
expected depth (channel Z) and every further layer asked for (:data:`LAYER_CHANNELS`).  A render
into a file asks for the layers its format holds by default (:attr:`ImageFormat.render_layers`):
so ``-o x.exr`` renders the depth layer, ``-o x.png`` not; ``--layers`` asks for others
(:mod:`splatgl.imagefiles.layer_files` writes them: EXR channels, or a picture per layer).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..errors import SplatglError
from ..output.layers import BASE, Layer

#: Bits per channel an integer format can be written with (``--bit-depth``).
BIT_DEPTHS = (8, 16)

#: The channels each layer adds to a file, in file order (EXR's ``layer.channel`` names for the
#: layers beyond colour, alpha and depth).  Z is the expected depth ``D / A`` and N the unit
#: normal; ``count`` and ``id`` are float32 (exact to 2^24).
LAYER_CHANNELS: dict[Layer, tuple[str, ...]] = {
    Layer.COLOUR: ("R", "G", "B"),
    Layer.ALPHA: ("A",),
    Layer.DEPTH: ("Z",),
    Layer.MEDIAN_DEPTH: ("median.Z",),
    Layer.NORMAL: ("N.X", "N.Y", "N.Z"),
    Layer.COUNT: ("count",),
    Layer.TOP_ID: ("id",),
}


@dataclass(frozen=True)
class ImageFormat:
    """One image format: ``name`` (the ``--format`` value), its ``suffixes`` (lower case, the
    usual one first), whether its channels are float32 (``is_float``; else integers of
    :data:`BIT_DEPTHS` bits) and the ``layers`` a file of it holds."""

    name: str
    suffixes: tuple[str, ...]
    is_float: bool
    layers: frozenset[Layer]

    @property
    def suffix(self) -> str:
        return self.suffixes[0]

    @property
    def bit_depths(self) -> tuple[int, ...]:
        """The bits per channel it is written with (none to choose for a float format)."""
        return () if self.is_float else BIT_DEPTHS

    @property
    def render_layers(self) -> frozenset[Layer]:
        """The layers a render into this format asks for unless told (every render has
        :data:`BASE`; a float format: the depth besides)."""
        return BASE | (self.layers & DEFAULT_FLOAT_LAYERS)

    def channels(self, layers: frozenset[Layer] | set[Layer]) -> tuple[str, ...]:
        """The channel names of a file of this format written from ``layers`` (those of them it
        holds, in :data:`LAYER_CHANNELS` order)."""
        return tuple(c for layer, names in LAYER_CHANNELS.items()
                     if layer in layers and layer in self.layers for c in names)


#: Every image format :func:`splatgl.imagefiles.images.write_image` writes, in the order messages
#: and ``--format`` list them.
IMAGE_FORMATS: tuple[ImageFormat, ...] = (
    ImageFormat("png", (".png",), False, frozenset({Layer.COLOUR})),
    ImageFormat("tif", (".tif", ".tiff"), False, frozenset({Layer.COLOUR})),
    ImageFormat("exr", (".exr",), True, frozenset(Layer)),
)
#: The layers an EXR render holds unless ``--layers`` says otherwise.
DEFAULT_FLOAT_LAYERS = frozenset({Layer.COLOUR, Layer.ALPHA, Layer.DEPTH})
#: The format of frames written into a folder unless ``--format`` says otherwise.
DEFAULT_FORMAT = IMAGE_FORMATS[0]
#: Every suffix of :data:`IMAGE_FORMATS`.
IMAGE_SUFFIXES = tuple(s for fmt in IMAGE_FORMATS for s in fmt.suffixes)
#: The ``--format`` choices.
FORMAT_NAMES = tuple(fmt.name for fmt in IMAGE_FORMATS)
#: The formats of pictures for people (a depth preview, a heat map): colour only, integers.
PICTURE_FORMATS = tuple(fmt for fmt in IMAGE_FORMATS if not fmt.is_float)
_BY_SUFFIX = {s: fmt for fmt in IMAGE_FORMATS for s in fmt.suffixes}


def suffix_list(formats=IMAGE_FORMATS, last: str = " or ") -> str:
    """``".png, .tif or .exr"``: the usual suffixes of ``formats`` (``last`` before the last)."""
    names = [fmt.suffix for fmt in formats]
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + last + names[-1]


def find_format(path: str | Path) -> ImageFormat | None:
    """The format ``path``'s suffix names, or None."""
    return _BY_SUFFIX.get(Path(path).suffix.lower())


def image_format(path: str | Path, what: str = "") -> ImageFormat:
    """The format of ``path`` (by its suffix); a name no format has is refused in one line
    (before any work), which ``what`` (an option name) starts."""
    path = Path(path)
    fmt = find_format(path)
    if fmt is None:
        ext = path.suffix.lower()
        got = f"'{ext}'" if ext else "no suffix"
        raise SplatglError(f"{what + ' ' if what else ''}{path}: unsupported image format ({got}); "
                           f"use {', '.join(IMAGE_SUFFIXES[:-1])} or {IMAGE_SUFFIXES[-1]}")
    return fmt


def format_named(name: str) -> ImageFormat | None:
    """The format called ``name`` (``png``, ``.TIF``, ``tiff``: case and a leading dot are
    ignored, any suffix of a format names it), or None."""
    key = name.lower().lstrip(".")
    return next((fmt for fmt in IMAGE_FORMATS if key == fmt.name or "." + key in fmt.suffixes), None)


def picture_format(path: str | Path, what: str) -> ImageFormat:
    """The format of ``path``, which must be one of :data:`PICTURE_FORMATS` (a colourised
    preview has no float data to keep); refused in one line naming ``what`` (an option)."""
    fmt = find_format(path)
    if fmt not in PICTURE_FORMATS:
        names = " or ".join(f.suffix for f in PICTURE_FORMATS)
        raise SplatglError(f"{path}: {what} needs a {names} file name")
    return fmt
