"""Lossless WebP images as (H, W, 4) uint8 RGBA arrays (the textures of SOG files), via Pillow.

Pillow writes exact lossless WebP (``exact=True`` keeps the RGB of transparent texels, which SOG
uses as data).  OpenImageIO, splatgl's image library, does not: its WebP output changed texel
values even when asked for lossless (checked with OpenImageIO 3.2), so SOG needs Pillow.
"""

from __future__ import annotations

import io
import warnings

import numpy as np

from ..errors import SceneFormatError

#: WebP's largest image edge.
MAX_EDGE = 16383
#: Lossless effort: ``method`` 0-6 and ``quality`` (for lossless, the effort spent on size).
#: 2 / 50 keeps a 150k-splat scene's textures at about a second on a slow CPU.
METHOD = 2
QUALITY = 50


def encode(rgba: np.ndarray) -> bytes:
    """Lossless WebP bytes of the (H, W, 4) uint8 array ``rgba``."""
    from PIL import Image
    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(rgba, np.uint8), "RGBA").save(
        buf, "WEBP", lossless=True, exact=True, quality=QUALITY, method=METHOD)
    return buf.getvalue()


def decode(path, blob: bytes, what: str, min_texels: int = 0,
           max_texels: int = MAX_EDGE * MAX_EDGE) -> np.ndarray:
    """(H, W, 4) uint8 RGBA of the WebP ``blob``; any decoding failure, or a size outside
    ``[min_texels, max_texels]``, becomes a :class:`SceneFormatError` naming ``what``."""
    from PIL import Image
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            img = Image.open(io.BytesIO(blob), formats=["WEBP"])
            w, h = img.size
            if not min_texels <= w * h <= max_texels:
                raise SceneFormatError(path, f"texture is {w} x {h} texels; expected between "
                                             f"{min_texels} and {max_texels}", what)
            arr = np.asarray(img.convert("RGBA"))
    except SceneFormatError:
        raise
    except Exception as exc:  # Pillow raises many kinds (OSError, SyntaxError, ValueError, ...)
        raise SceneFormatError(path, f"not a readable WebP image ({type(exc).__name__}: "
                                     f"{str(exc)[:120]})", what) from None
    return arr
