"""Geometry to composite splats into (``--under FILE.exr``), as data: a render of opaque
geometry made from the same camera (:class:`UnderImage`, read from its file by
:func:`splatgl.imagefiles.under_exr.read_under`), and the compositing rule.

The renderers drop every splat fragment at or behind the geometry (its depth, in the same
metric, against the pixel's: :class:`UnderLayer` ``depth``) and composite what remains over the
geometry's colour with the splats' transmittance (:func:`composite_under`)::

    rgb = C + T (U_rgb + (1 - U_a) background),   alpha = 1 - T (1 - U_a)

so the geometry shows exactly where and as much as the splats in front of it let through.
The accumulated depth adds the geometry's with the same weight (:func:`composite_depth`); the
other layers (median depth, normal, count, top contributor) are the splats' in front of it.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import SplatglError


class DepthKind(enum.Enum):
    """What a geometry depth channel holds (world units): view-space z, or the distance from
    the camera along each pixel's ray."""

    Z = "z"
    DISTANCE = "distance"


@dataclass(frozen=True)
class UnderImage:
    """Geometry to composite into, row 0 at the top (read from a file by
    :func:`splatgl.imagefiles.under_exr.read_under`).

    Attributes: ``rgb`` (H, W, 3) float32 premultiplied colour; ``alpha`` (H, W) float32 (1
    where the file has no A); ``depth`` (H, W) float32 in ``kind``, +inf where there is no
    geometry; ``path`` the file.
    """

    rgb: np.ndarray
    alpha: np.ndarray
    depth: np.ndarray
    kind: DepthKind
    path: Path

    @property
    def size(self) -> tuple[int, int]:
        """(width, height)."""
        return self.depth.shape[1], self.depth.shape[0]

    def check_size(self, width: int, height: int) -> None:
        """Refuse (one line) an image of another size than the view's."""
        if self.size != (width, height):
            raise SplatglError(f"--under {self.path}: the geometry is {self.size[0]}x{self.size[1]}, "
                               f"the view {width}x{height}; render both from the same camera")


@dataclass(frozen=True)
class UnderLayer:
    """Geometry as the renderers take it: ``rgb`` (H, W, 3) premultiplied and ``alpha``
    (H, W) as in :class:`UnderImage`, ``depth`` (H, W) float32 in the view's own depth metric
    (:meth:`splatgl.cameras.model.CameraModel.pixel_depth`; +inf where there is no geometry)."""

    rgb: np.ndarray
    alpha: np.ndarray
    depth: np.ndarray


def composite_under(premultiplied: np.ndarray, alpha: np.ndarray, under: UnderLayer,
                    background) -> np.ndarray:
    """(H, W, 4) float32: splats ``premultiplied`` (H, W, 3) ``C`` with accumulated ``alpha``
    (H, W) ``A = 1 - T`` over the geometry (module doc)."""
    t = (1.0 - np.asarray(alpha, np.float32))[..., None]
    u_a = under.alpha[..., None]
    bg = np.asarray(background, np.float32)
    rgb = premultiplied + t * (under.rgb + (1.0 - u_a) * bg)
    a = 1.0 - t * (1.0 - u_a)
    return np.concatenate([rgb, a], -1).astype(np.float32)


def composite_depth(depth: np.ndarray, alpha: np.ndarray, under: UnderLayer) -> np.ndarray:
    """(H, W) float32 accumulated depth of the composite: the splats' ``D`` plus the geometry's
    depth with its weight ``T U_a`` where it has one (so ``D / A`` of the composite's alpha is
    its expected depth)."""
    t = 1.0 - np.asarray(alpha, np.float32)
    has = np.isfinite(under.depth)
    return (depth + np.where(has, t * under.alpha * np.where(has, under.depth, 0.0), 0.0)
            ).astype(np.float32)
