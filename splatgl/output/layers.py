"""The images a render returns, and how a caller asks for them.

Every render returns colour and alpha; further layers are asked for as data, a set of
:class:`Layer` (``layers=with_layers(Layer.DEPTH)``), which each renderer reads: the quad path
then adds the target and shader outputs a layer needs, the tile renderer and the reference their
buffers.  A new layer is one member here, its output in each renderer, and its channels in the
image table (:data:`splatgl.output.image_formats.LAYER_CHANNELS`).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

from ..errors import SplatglError

#: Below this accumulated alpha the expected depth ``D / A`` is meaningless and is masked (0).
MIN_DEPTH_ALPHA = 1e-3


class Layer(enum.Enum):
    """A layer of a render (the values are the names a command line gives)."""

    #: ``C + (1 - A) background``, RGB.
    COLOUR = "colour"
    #: ``A = 1 - T_final``.
    ALPHA = "alpha"
    #: The accumulated depth ``D = sum z alpha T`` (weighted like the colour; the expected
    #: depth is ``D / A``).
    DEPTH = "depth"


#: What every render returns.
BASE: frozenset[Layer] = frozenset({Layer.COLOUR, Layer.ALPHA})


def with_layers(*layers: Layer | str) -> frozenset[Layer]:
    """:data:`BASE` and ``layers`` (members or their names)."""
    return BASE | {as_layer(layer) for layer in layers}


def as_layer(value: Layer | str) -> Layer:
    """``value`` as a :class:`Layer`; a one-line error naming the choices otherwise."""
    try:
        return Layer(value)
    except ValueError:
        names = ", ".join(m.value for m in Layer)
        raise SplatglError(f"unknown layer {value!r}; the layers are {names}") from None


def parse_layers(text: str) -> frozenset[Layer]:
    """``"colour,alpha,depth"`` (comma-separated names) as a layer set, always with :data:`BASE`."""
    names = [part.strip() for part in text.split(",") if part.strip()]
    return with_layers(*names)


@dataclass(frozen=True)
class RenderOutput:
    """Layers of one view, all float32 with row 0 at the top of the image.

    Attributes:
        rgba: (H, W, 4) ``C + (1 - A) background`` and ``A``.
        depth: (H, W) accumulated depth ``D = sum z alpha T`` (z = camera-space z, world units),
            weighted exactly like the colour; zeros (or None) when the depth layer was not
            asked for.
        layers: the layers this output holds.
    """

    rgba: np.ndarray
    depth: np.ndarray | None
    layers: frozenset[Layer] = BASE

    @property
    def alpha(self) -> np.ndarray:
        return self.rgba[..., 3]

    def expected_depth(self, min_alpha: float = MIN_DEPTH_ALPHA) -> np.ndarray:
        """(H, W) ``D / A``, the alpha-normalised depth; 0 where ``A < min_alpha``."""
        a = self.alpha
        ok = a >= min_alpha
        return np.where(ok, self.depth / np.where(ok, a, 1.0), 0.0).astype(np.float32)
