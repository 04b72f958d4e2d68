"""antimatter15 ``.splat`` files: 32 bytes per splat, no header, no magic.

Row layout (little endian)::

    bytes  0..11  position    3 x float32 (world units)
    bytes 12..23  scale       3 x float32, linear (not log)
    bytes 24..27  colour      4 x uint8 RGBA: RGB = 255 (0.5 + SH_C0 f_dc), A = 255 sigmoid(o)
    bytes 28..31  rotation    4 x uint8 (w, x, y, z) = clip(q 128 + 128, 0, 255), q unit length

Only SH degree 0 fits; 3D Gaussians only.  Alpha 0 and 255 map to opacity logits of -+40 (the
clamp :meth:`Scene.from_activated` uses), so every stored value stays finite.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np

from ..constants import MAX_LOGIT, SH_C0
from ..errors import SceneFormatError
from ..scene.splats import Scene, SplatKind, activate
from . import quantise as qz
from ._memory import check_memory
from ._messages import reader_guard

NAME = "splat"
EXTENSIONS = (".splat",)
#: No signature: chosen by extension only, after every format with magic bytes declined.
NEEDS_MAGIC = False
#: Bytes per splat.
ROW_BYTES = 32

ROW_DTYPE = np.dtype([("position", "<f4", 3), ("scale", "<f4", 3), ("rgba", "u1", 4),
                      ("rotation", "u1", 4)])
assert ROW_DTYPE.itemsize == ROW_BYTES


def sniff(head: bytes) -> bool:
    """Always False: a .splat file has no magic bytes, so it is recognised by extension only."""
    return False


@reader_guard
def read(path: Path, drop_invalid: bool = False) -> Scene:
    """Load a .splat file: log of the scales, logit of alpha, f_dc from RGB, rotation bytes
    decoded as ``(b - 128) / 128`` (normalised later by :attr:`Scene.rotations`)."""
    try:
        size = os.path.getsize(path)
        if size % ROW_BYTES:
            raise SceneFormatError(
                path, f"size {size} bytes is not a multiple of {ROW_BYTES} (bytes per splat): "
                f"{size // ROW_BYTES} whole splats and {size % ROW_BYTES} bytes left over "
                "(truncated file, or not a .splat file)")
        # the rows, then float64 colours and scales and their float32 results (~150 B/splat)
        check_memory(path, size // ROW_BYTES, 1, 150, size)
        rows = np.fromfile(path, dtype=ROW_DTYPE)
    except OSError as exc:
        raise SceneFormatError(path, f"cannot read: {exc.strerror or exc}") from None
    return decode(path, rows, drop_invalid)


def decode(path, rows: np.ndarray, drop_invalid: bool = False) -> Scene:
    """The scene of (N,) :data:`ROW_DTYPE` ``rows`` (all of ``path``'s, or a block of them)."""
    means = rows["position"]
    with np.errstate(divide="ignore", invalid="ignore"):
        log_scales = np.log(rows["scale"].astype(np.float64)).astype(np.float32)
    rgba = rows["rgba"].astype(np.float64) / 255.0
    dc = ((rgba[:, :3] - 0.5) / SH_C0).astype(np.float32)
    a = rgba[:, 3]
    with np.errstate(divide="ignore"):
        logits = np.clip(np.log(a) - np.log1p(-a), -MAX_LOGIT, MAX_LOGIT).astype(np.float32)
    quats = ((rows["rotation"].astype(np.float32) - 128.0) / 128.0)
    return activate(path, means, quats, log_scales, logits, dc[:, None, :],
                    SplatKind.GAUSSIAN_3D, drop_invalid)


def encode(scene: Scene, path=None) -> np.ndarray:
    """The (N,) :data:`ROW_DTYPE` rows of ``scene`` (quantised colour, alpha and rotation)."""
    if scene.kind is not SplatKind.GAUSSIAN_3D:
        raise SceneFormatError(path, ".splat stores 3D Gaussians only; cannot write a 2DGS "
                                     "surfel scene (write .ply instead)", "scale")
    qz.check_linear_scales(scene, path, ".splat")
    if scene.sh_degree > 0:
        warnings.warn(f".splat stores SH degree 0 only; dropping degrees 1..{scene.sh_degree}",
                      stacklevel=3)
    rows = np.zeros(scene.count, ROW_DTYPE)
    rows["position"] = scene.means
    rows["scale"] = scene.scales
    colour = 255.0 * (0.5 + SH_C0 * scene.sh[:, 0].astype(np.float64))
    rows["rgba"][:, :3] = np.clip(np.rint(colour), 0, 255)
    rows["rgba"][:, 3] = np.clip(np.rint(255.0 * scene.opacities.astype(np.float64)), 0, 255)
    q = scene.rotations.astype(np.float64)
    rows["rotation"] = np.clip(np.rint(q * 128.0 + 128.0), 0, 255)
    return rows


def write(path, scene: Scene) -> None:
    """Write ``scene`` as .splat (lossy: 8-bit colour, alpha and rotation; SH degree 0)."""
    encode(scene, path).tofile(path)


def error_bounds(scene: Scene) -> dict:
    """Round-trip bounds (units as in :mod:`splatgl.formats.quantise`): float32 position and
    linear scale (``2^-24 (1 + |log s|)`` relative, from the log of the rounded exp), 8-bit
    opacity, 8-bit colour clipped to 0..255 (plus the distance clipped), and rotation bytes
    ``rint(128 q + 128)``: at most 0.5/128 per component, 1/128 for one clipping at 127/128, so
    ``|q' - q| <= sqrt(1.75)/128`` and the angle ``<= 2 asin(sqrt(1.75)/128)``."""
    import math
    colour = 0.5 + SH_C0 * scene.sh[:, 0].astype(np.float64)
    clipped = float(max(0.0, -colour.min(), colour.max() - 1.0)) if scene.count else 0.0
    max_log = float(np.abs(scene.log_scales).max()) if scene.count else 0.0
    return {
        "position": 0.0,
        "scale": 2.0 ** -24 * (1.0 + max_log) * (1 + 1e-6) + 1e-9,
        "opacity": 0.5 / 255.0 + 1e-6,
        "rotation": math.degrees(2.0 * math.asin(math.sqrt(1.75) / 128.0)),
        "color": 0.5 / 255.0 + clipped + 1e-6,
        "sh_rest": None,
    }
