"""An image made by another program, read for scoring against the reference
(``splatgl compare --image``, the conformance kit).

Checks, each a one-line :class:`~splatgl.errors.SplatglError` naming the file, so that a
convention mismatch reads as what it is rather than as a low PSNR:

- before rendering (:func:`read_their_image`): the file reads (PNG, EXR, WebP, JPEG, TIFF; 8 or
  16 bits or float), its values are finite, and its size is the camera's (a few pixels off,
  transposed or a scaled size are named as such);
- against the reference (:func:`match_to_reference`): an image upside down or mirrored
  (refused unless ``flip``/``mirror`` say to turn it), the alpha convention of an image with an
  alpha channel (``straight``: colour not multiplied by alpha; ``premultiplied``; ``composited``:
  the background already in the colour; ``auto`` picks the one closest to the reference and
  says which), and the background of an image without one (where the reference is empty, the
  image must show the background it is scored with).

The scored colour is always ``C + (1 - A) background`` (splatgl's composited RGB).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from ...errors import SplatglError
from ...imagefiles.images import quiet_image_library
from .metrics import psnr

#: Alpha conventions ``--alpha`` accepts.
ALPHA_CONVENTIONS = ("auto", "straight", "premultiplied", "composited")
#: A size this many pixels or fewer off the camera's (either side) is reported as "a few
#: pixels off" (a renderer rounding its size, or cropping a border).
NEAR_SIZE = 8
#: An image turned (flipped in y or mirrored in x) scores at least this many dB better turned
#: before it is refused as turned (and at least TURNED_MIN_PSNR dB): a symmetric scene
#: scores about the same either way and is left alone.
TURNED_MARGIN_DB = 3.0
TURNED_MIN_PSNR = 20.0
#: Where the reference's alpha is below this the pixel is "empty" for the background check,
#: which needs at least EMPTY_MIN_SHARE of the pixels empty, and refuses a median colour
#: there more than BACKGROUND_TOLERANCE off the background in any channel.
EMPTY_ALPHA = 0.01
EMPTY_MIN_SHARE = 0.01
BACKGROUND_TOLERANCE = 0.05


@dataclass(frozen=True)
class TheirImage:
    """Pixels of another program's image (row 0 at the top as stored, float, [0, 1] for
    integer files).  rgb: (H, W, 3); alpha: (H, W) or None; bits: 8, 16 or None (float)."""

    path: Path
    rgb: np.ndarray
    alpha: np.ndarray | None
    bits: int | None


@dataclass(frozen=True)
class Matched:
    """The image as scored: ``rgb`` (H, W, 3) composited like splatgl's, ``alpha`` (H, W) or
    None, and what was done to get there (``notes``, lines for the report)."""

    rgb: np.ndarray
    alpha: np.ndarray | None
    convention: str
    flipped: bool = False
    mirrored: bool = False
    notes: tuple[str, ...] = field(default_factory=tuple)


def read_their_image(path: str | Path, width: int, height: int) -> TheirImage:
    """Read ``path`` and check its size against the camera's ``width`` x ``height``."""
    path = Path(path)
    if not path.is_file():
        raise SplatglError(f"--image {path}: no such file")
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)      # the stored values, not premultiplied
    with quiet_image_library():   # libpng's own "libpng error:" line: the reason is below
        inp = oiio.ImageInput.open(str(path), config)
    if inp is None:
        raise SplatglError(f"--image {path}: not a readable image ({' '.join(oiio.geterror().split())})")
    try:
        spec = inp.spec()
        _check_size(path, spec.width, spec.height, width, height)
        with quiet_image_library():
            pixels = inp.read_image(oiio.FLOAT)
        if pixels is None:
            raise SplatglError(f"--image {path}: cannot read its pixels ({' '.join(inp.geterror().split())})")
        pixels = np.asarray(pixels, np.float32).reshape(spec.height, spec.width, spec.nchannels)
        names = [n.upper() for n in spec.channelnames]
        alpha_at = spec.alpha_channel if spec.alpha_channel >= 0 else (names.index("A") if "A" in names else -1)
        bits = {"uint8": 8, "uint16": 16}.get(str(spec.format))
    finally:
        inp.close()
    colour = [i for i in range(pixels.shape[2]) if i != alpha_at][:3]
    rgb = pixels[..., colour]
    if rgb.shape[2] == 1:
        rgb = np.repeat(rgb, 3, axis=2)          # grey
    elif rgb.shape[2] == 2:
        raise SplatglError(f"--image {path}: has 2 colour channels; expected grey, RGB or RGBA")
    alpha = pixels[..., alpha_at] if alpha_at >= 0 else None
    bad = int((~np.isfinite(rgb)).any(axis=2).sum())
    if bad:
        raise SplatglError(f"--image {path}: {bad} pixels hold NaN or Inf")
    return TheirImage(path, rgb, alpha, bits)


def _check_size(path: Path, w: int, h: int, width: int, height: int) -> None:
    if (w, h) == (width, height):
        return
    where = f"--image {path}: the image is {w}x{h}, the camera {width}x{height}"
    if (w, h) == (height, width):
        raise SplatglError(f"{where}: width and height swapped (a transposed or rotated image)")
    if abs(w - width) <= NEAR_SIZE and abs(h - height) <= NEAR_SIZE:
        parts = [f"{abs(d)} pixel{'s' if abs(d) != 1 else ''} {word[d > 0]}"
                 for d, word in ((w - width, ("narrower", "wider")), (h - height, ("shorter", "taller")))
                 if d]
        raise SplatglError(f"{where}: {' and '.join(parts)}, a few pixels off (a renderer that "
                           f"rounds its size or crops a border); render it at {width}x{height}")
    if w * height == h * width:
        raise SplatglError(f"{where}: the same aspect at another size; pass --width {w} --height {h} "
                           "to score it at its own size")
    raise SplatglError(f"{where}; render it from the same camera (--camera) at {width}x{height}")


def _composite(img: TheirImage, convention: str, background: np.ndarray) -> np.ndarray:
    """The image as ``C + (1 - A) bg`` under an alpha ``convention``."""
    if img.alpha is None or convention == "composited":
        return img.rgb
    a = img.alpha[..., None]
    colour = img.rgb * a if convention == "straight" else img.rgb
    return colour + (1.0 - a) * background


def match_to_reference(img: TheirImage, reference_rgb: np.ndarray, reference_alpha: np.ndarray,
                       background=(0.0, 0.0, 0.0), alpha: str = "auto", flip: bool = False,
                       mirror: bool = False) -> Matched:
    """The image turned and composited as asked, after the checks of the module doc.

    ``reference_rgb`` (H, W, 3) composited and ``reference_alpha`` (H, W): the reference's
    render of the same camera; ``background`` what both are composited over."""
    if alpha not in ALPHA_CONVENTIONS:
        raise SplatglError(f"--alpha must be one of {', '.join(ALPHA_CONVENTIONS)}, got {alpha!r}")
    bg = np.asarray(background, np.float32)
    notes = []
    if flip or mirror:
        axes = tuple(a for a, on in ((0, flip), (1, mirror)) if on)
        img = TheirImage(img.path, np.flip(img.rgb, axes),
                         None if img.alpha is None else np.flip(img.alpha, axes), img.bits)
        notes.append("turned as asked: " + " and ".join(
            w for w, on in (("flipped in y", flip), ("mirrored in x", mirror)) if on))
    conventions = ["composited"] if img.alpha is None else (
        [alpha] if alpha != "auto" else ["premultiplied", "straight", "composited"])
    scores = {c: psnr(_composite(img, c, bg), reference_rgb) for c in conventions}
    convention = max(scores, key=scores.get)
    rgb = _composite(img, convention, bg)
    _check_turned(img.path, rgb, reference_rgb, scores[convention], flip, mirror)
    if img.alpha is not None:
        if alpha == "auto":
            others = ", ".join(f"{c} {_db(v)}" for c, v in scores.items() if c != convention)
            notes.append(f"alpha read as {convention} (closest to the reference, {_db(scores[convention])}; "
                         f"{others})")
        else:
            notes.append(f"alpha read as {convention} (--alpha)")
    if img.alpha is None or convention == "composited":
        _check_background(img.path, rgb, reference_alpha, bg)
    return Matched(rgb.astype(np.float32), img.alpha, convention, flip, mirror, tuple(notes))


def _db(value: float) -> str:
    return "inf dB" if value == float("inf") else f"{value:.1f} dB"


def _check_turned(path: Path, rgb: np.ndarray, ref: np.ndarray, as_is: float, flip: bool,
                  mirror: bool) -> None:
    """Refuse an image that scores much better upside down or mirrored (or, turned as asked,
    much better turned back)."""
    for axis, what, option, done in ((0, "upside down (its row 0 is the bottom; splatgl's is the top)",
                                      "--flip-y", flip),
                                     (1, "mirrored left to right", "--mirror-x", mirror)):
        turned = psnr(np.flip(rgb, axis), ref)
        if turned < TURNED_MIN_PSNR or turned < as_is + TURNED_MARGIN_DB:
            continue
        if done:
            raise SplatglError(f"--image {path}: scores {_db(turned)} turned back, {_db(as_is)} "
                               f"with {option}; leave {option} out")
        raise SplatglError(f"--image {path}: looks {what}: {_db(turned)} against the reference "
                           f"turned, {_db(as_is)} as it is; pass {option} to score it turned")


def _check_background(path: Path, rgb: np.ndarray, ref_alpha: np.ndarray, bg: np.ndarray) -> None:
    """Where the reference is empty, the image must show the background it is scored with."""
    empty = ref_alpha < EMPTY_ALPHA
    if empty.mean() < EMPTY_MIN_SHARE:
        return
    seen = np.median(rgb[empty], axis=0)
    if np.abs(seen - bg).max() > BACKGROUND_TOLERANCE:
        shown = ",".join(f"{v:.3g}" for v in seen)
        want = ",".join(f"{v:g}" for v in bg)
        raise SplatglError(f"--image {path}: where the reference is empty ({empty.mean() * 100:.0f}% of "
                           f"the pixels) the image shows {shown}, not the background {want}: pass "
                           f"--background {shown} (or render it over {want})")
