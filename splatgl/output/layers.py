"""What a renderer returns when asked for more than colour: colour, alpha and depth layers."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Below this accumulated alpha the expected depth ``D / A`` is meaningless and is masked (0).
MIN_DEPTH_ALPHA = 1e-3


@dataclass(frozen=True)
class RenderOutput:
    """Layers of one view, all float32 with row 0 at the top of the image.

    Attributes:
        rgba: (H, W, 4) ``C + (1 - A) background`` and ``A``.
        depth: (H, W) accumulated depth ``D = sum z alpha T`` (z = camera-space z, world units),
            weighted exactly like the colour.
    """

    rgba: np.ndarray
    depth: np.ndarray

    @property
    def alpha(self) -> np.ndarray:
        return self.rgba[..., 3]

    def expected_depth(self, min_alpha: float = MIN_DEPTH_ALPHA) -> np.ndarray:
        """(H, W) ``D / A``, the alpha-normalised depth; 0 where ``A < min_alpha``."""
        a = self.alpha
        ok = a >= min_alpha
        return np.where(ok, self.depth / np.where(ok, a, 1.0), 0.0).astype(np.float32)
