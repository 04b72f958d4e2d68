"""The images a render returns, and how a caller asks for them.

Every render returns colour and alpha; further layers are asked for as data, a set of
:class:`Layer` (``layers=with_layers(Layer.DEPTH, Layer.NORMAL)``, or ``parse_layers("depth,
normal")`` from ``--layers``), which each renderer reads: the quad path then adds the target,
shader outputs or pass a layer needs, the tile renderer and the reference their buffers, and a
layer not asked for costs nothing.  A new layer is one member here, its output in each renderer,
and its channels in the image table (:data:`splatgl.imagefiles.image_formats.LAYER_CHANNELS`).

What each layer holds (``z`` is a splat's depth: camera-space z for perspective and
orthographic cameras, the distance from the camera for fisheye and equirectangular ones; a 2DGS
surfel's is the depth of the ray's hit per pixel; weights ``w_k = alpha_k T_k`` as for colour):

- ``depth``: the accumulated ``D = sum z w`` (the expected depth is ``D / A``);
- ``median-depth``: the ``z`` of the last splat blended while ``T > 0.5``, i.e. where the
  accumulated alpha crosses 0.5 (2DGS's and gsplat's rule; a pixel whose alpha never reaches
  0.5 keeps its last splat's ``z``), 0 where nothing blended;
- ``normal``: the accumulated ``N = sum n w`` of unit normals in camera space (3DGS: the axis of
  the smallest scale, 2DGS: the surfel's normal, each turned towards the camera), normalised
  where ``A > 0`` (:meth:`RenderOutput.unit_normals`);
- ``count``: how many splats blended into the pixel (alpha >= 1/255, before the early stop);
- ``top-id``: the scene row of the splat with the largest weight (the first of equal ones), -1
  where none blended.
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
    #: The depth where the accumulated alpha crosses 0.5 (module doc).
    MEDIAN_DEPTH = "median-depth"
    #: The blended splat normals, camera space (module doc).
    NORMAL = "normal"
    #: The number of splats blended into each pixel.
    COUNT = "count"
    #: The scene row of the splat with the largest weight, -1 where none.
    TOP_ID = "top-id"


#: What every render returns.
BASE: frozenset[Layer] = frozenset({Layer.COLOUR, Layer.ALPHA})
#: The layers that follow the running transmittance with a threshold (not plain weighted sums):
#: the quad path computes them in an ordered pass of their own (docs/layers.md).
ORDERED: frozenset[Layer] = frozenset({Layer.MEDIAN_DEPTH, Layer.COUNT, Layer.TOP_ID})


class NormalSpace(enum.Enum):
    """Where normals are expressed: the camera's OpenCV axes (x right, y down, z forward) or
    the world's (the camera's world frame; a scene's ``--transform`` is undone by neither)."""

    CAMERA = "camera"
    WORLD = "world"


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


def parse_layer_names(text: str, what: str = "--layers") -> tuple[Layer, ...]:
    """``"colour,depth,normal"`` as the layers named, in the order given (duplicates dropped);
    an unknown or empty name is refused in one line starting with ``what``."""
    names = [part.strip() for part in text.split(",")]
    if not any(names):
        raise SplatglError(f"{what}: name at least one layer ({', '.join(m.value for m in Layer)})")
    out: list[Layer] = []
    for name in names:
        if not name:
            raise SplatglError(f"{what} {text}: an empty name between commas")
        try:
            layer = as_layer(name)
        except SplatglError as exc:
            raise SplatglError(f"{what}: {exc}") from None
        if layer not in out:
            out.append(layer)
    return tuple(out)


def parse_layers(text: str) -> frozenset[Layer]:
    """``"colour,alpha,depth"`` (comma-separated names) as a layer set, always with :data:`BASE`."""
    return BASE | frozenset(parse_layer_names(text))


#: The per-pixel arrays of a :class:`RenderOutput` besides ``rgba``, by the layer that fills them.
PLANES: dict[Layer, str] = {Layer.DEPTH: "depth", Layer.MEDIAN_DEPTH: "median_depth",
                            Layer.NORMAL: "normal", Layer.COUNT: "count", Layer.TOP_ID: "top_id"}


@dataclass(frozen=True)
class RenderOutput:
    """Layers of one view, row 0 at the top of the image (module doc for their meaning).

    Attributes:
        rgba: (H, W, 4) float32 ``C + (1 - A) background`` and ``A``.
        depth: (H, W) float32 accumulated depth ``D = sum z alpha T`` (world units), weighted
            exactly like the colour; zeros (or None) when the depth layer was not asked for.
        layers: the layers this output holds.
        normal: (H, W, 3) float32 accumulated camera-space normal ``N = sum n alpha T``.
        median_depth: (H, W) float32 median depth (0 where nothing blended).
        count: (H, W) uint32 splats blended.
        top_id: (H, W) int64 scene row of the largest weight (-1: none).
        Each of the last four is None unless its layer was asked for.
    """

    rgba: np.ndarray
    depth: np.ndarray | None
    layers: frozenset[Layer] = BASE
    normal: np.ndarray | None = None
    median_depth: np.ndarray | None = None
    count: np.ndarray | None = None
    top_id: np.ndarray | None = None

    @property
    def alpha(self) -> np.ndarray:
        return self.rgba[..., 3]

    def expected_depth(self, min_alpha: float = MIN_DEPTH_ALPHA) -> np.ndarray:
        """(H, W) ``D / A``, the alpha-normalised depth; 0 where ``A < min_alpha``."""
        a = self.alpha
        ok = a >= min_alpha
        return np.where(ok, self.depth / np.where(ok, a, 1.0), 0.0).astype(np.float32)

    def unit_normals(self, world_to_camera: np.ndarray | None = None) -> np.ndarray:
        """(H, W, 3) float32 ``N / |N|`` where ``A > 0`` and ``|N| > 0``, else 0: in camera
        space, or in world space given the camera's (4, 4) ``world_to_camera`` (its rotation
        ``R``: ``n_world = R^T n_camera``)."""
        return unit_normals(self.normal, self.alpha, world_to_camera)

    def planes(self) -> dict[str, np.ndarray]:
        """Every array this output holds, by field name (``rgba`` first)."""
        out = {"rgba": self.rgba}
        out.update({name: getattr(self, name) for name in PLANES.values()
                    if getattr(self, name) is not None})
        return out


def unit_normals(normal: np.ndarray, alpha: np.ndarray,
                 world_to_camera: np.ndarray | None = None) -> np.ndarray:
    """:meth:`RenderOutput.unit_normals` of an accumulated (H, W, 3) ``normal`` and (H, W)
    ``alpha``."""
    n = np.asarray(normal, np.float64)
    if world_to_camera is not None:
        rot = np.asarray(world_to_camera, np.float64)[:3, :3]
        rot = rot / np.cbrt(np.linalg.det(rot))    # a scaled pose: its rotation only
        n = n @ rot                                  # rows: (R^T n)^T = n^T R
    length = np.linalg.norm(n, axis=-1, keepdims=True)
    ok = (np.asarray(alpha)[..., None] > 0) & (length > 0)
    return np.where(ok, n / np.where(ok, length, 1.0), 0.0).astype(np.float32)


def concat_outputs(first: RenderOutput, second: RenderOutput, axis: int) -> RenderOutput:
    """``first`` and ``second`` joined along ``axis`` (1: side by side, 0: one above the
    other), every array both hold; the layers both hold."""
    a, b = first.planes(), second.planes()
    joined = {name: np.concatenate([a[name], b[name]], axis=axis) for name in a if name in b}
    return RenderOutput(joined.pop("rgba"), joined.pop("depth", None),
                        first.layers & second.layers, **joined)
