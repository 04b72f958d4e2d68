"""A render's layers written to files (``--layers``): one EXR with a channel per layer, or a
colourised picture per layer beside an integer image.

- EXR (:data:`~splatgl.imagefiles.image_formats.LAYER_CHANNELS`): R, G, B, A, Z (expected depth
  ``D / A``), ``median.Z``, ``N.X N.Y N.Z`` (unit normals), ``count`` and ``id`` (-1: none), all
  float32; the header says what the depths and normals are (``splatgl:depth`` ``z`` or
  ``distance``, ``splatgl:normal`` ``camera`` or ``world``), so the file can go back in as
  ``--under`` geometry;
- PNG / TIFF: the colour in the file named, and each other layer named in ``--layers`` as a
  picture with its scale beside it: ``NAME_depth.png``, ``NAME_median-depth.png``,
  ``NAME_normal.png``, ``NAME_count.png``, ``NAME_top-id.png``, ``NAME_alpha.png``
  (:func:`picture_path`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import SplatglError
from .image_formats import find_format
from .images import write_image
from ..output.layers import MIN_DEPTH_ALPHA, Layer, NormalSpace, RenderOutput
from .pictures import depth_preview, id_preview, normal_preview, value_preview
from ..output.under import DepthKind
from .under_exr import DEPTH_ATTRIBUTE

#: The EXR header attribute that says which space the normals are in.
NORMAL_ATTRIBUTE = "splatgl:normal"


@dataclass(frozen=True)
class LayerFiles:
    """How a render's layers go to files.

    Attributes:
        named: the layers named (``--layers``), in order; empty: the format's defaults (EXR:
            colour, alpha and depth; PNG/TIFF: colour alone).
        normal_space: the space normals are written in.
        world_to_camera: (4, 4) the camera's pose, for world-space normals (None: camera space).
        depth_kind: what the depths are: view z, or distance for fisheye and panorama cameras.
    """

    named: tuple[Layer, ...] = ()
    normal_space: NormalSpace = NormalSpace.CAMERA
    world_to_camera: np.ndarray | None = None
    depth_kind: DepthKind = DepthKind.Z

    def render_layers(self, path: str | Path) -> frozenset[Layer]:
        """The layers a render into ``path`` needs."""
        fmt = find_format(path)
        if not self.named:
            return fmt.render_layers
        return frozenset(self.named) | {Layer.COLOUR, Layer.ALPHA}

    def pictures(self, path: str | Path) -> tuple[Layer, ...]:
        """The layers written as pictures beside an integer image at ``path`` (none for EXR)."""
        fmt = find_format(path)
        if fmt is None or fmt.is_float:
            return ()
        return tuple(layer for layer in self.named if layer is not Layer.COLOUR)

    def paths(self, path: str | Path) -> list[Path]:
        """Every file a render into ``path`` writes: ``path`` and its pictures."""
        return [Path(path)] + [picture_path(path, layer) for layer in self.pictures(path)]


def picture_path(path: str | Path, layer: Layer) -> Path:
    """``NAME_<layer>.EXT`` beside ``NAME.EXT``."""
    path = Path(path)
    return path.with_name(f"{path.stem}_{layer.value}{path.suffix}")


def exr_channels(out: RenderOutput, layers: frozenset[Layer],
                 world_to_camera: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """The (H, W) float32 planes of ``layers`` beyond colour, alpha and depth, by channel name."""
    planes: dict[str, np.ndarray] = {}
    if Layer.MEDIAN_DEPTH in layers:
        planes["median.Z"] = out.median_depth
    if Layer.NORMAL in layers:
        n = out.unit_normals(world_to_camera)
        planes.update({"N.X": n[..., 0], "N.Y": n[..., 1], "N.Z": n[..., 2]})
    if Layer.COUNT in layers:
        planes["count"] = out.count.astype(np.float32)
    if Layer.TOP_ID in layers:
        planes["id"] = out.top_id.astype(np.float32)
    return planes


#: Float32 holds every whole number up to this exactly (the EXR ``id`` channel).
EXACT_FLOAT_IDS = 2 ** 24


def check_exact_ids(files: LayerFiles, path: str | Path, splats: int) -> None:
    """Refuse (before rendering) a top-id layer into an EXR for a scene whose splat indices a
    float32 channel cannot hold exactly."""
    if (Layer.TOP_ID in files.named and find_format(path).is_float
            and splats > EXACT_FLOAT_IDS):
        raise SplatglError(f"{path}: the EXR id channel is float32, exact up to "
                           f"{EXACT_FLOAT_IDS:,} splats, and this scene has {splats:,}; "
                           "use splatgl pixel or the Python API (RenderOutput.top_id) for its ids")


def layer_picture(out: RenderOutput, layer: Layer, files: LayerFiles) -> np.ndarray:
    """(H + bar, W, 4) the picture of ``layer`` (module doc)."""
    drawn = out.alpha >= MIN_DEPTH_ALPHA
    if layer is Layer.DEPTH:
        return depth_preview(out.expected_depth(), out.alpha)
    if layer is Layer.MEDIAN_DEPTH:
        return depth_preview(out.median_depth, out.alpha)
    if layer is Layer.ALPHA:
        return value_preview(out.alpha, np.ones_like(drawn), "alpha", top=1.0)
    if layer is Layer.NORMAL:
        n = out.unit_normals(files.world_to_camera)
        return normal_preview(n, out.alpha > 0, files.normal_space.value)
    if layer is Layer.COUNT:
        return value_preview(out.count.astype(np.float32), out.count > 0, "count", integer=True)
    if layer is Layer.TOP_ID:
        return id_preview(out.top_id)
    raise ValueError(f"no picture for {layer}")


def write_layers(path: str | Path, out: RenderOutput, files: LayerFiles, bit_depth: int = 8,
                 temp=lambda p: p, write=write_image,
                 attributes: dict[str, str] | None = None) -> None:
    """Write ``out`` to ``path`` (and its pictures), each through ``temp(final path)`` (the
    name to write to: an :class:`~splatgl.writing.outputs.OutputFiles` temporary, or the path)
    with ``write`` (:func:`~splatgl.imagefiles.images.write_image`'s signature); ``attributes``
    go into the header of ``path``'s file (a path frame's record)."""
    fmt = find_format(path)
    layers = files.render_layers(path)
    if fmt.is_float:
        depth = out.expected_depth() if Layer.DEPTH in layers else None
        extra = exr_channels(out, layers, files.world_to_camera)
        header = {**(attributes or {}), DEPTH_ATTRIBUTE: files.depth_kind.value}
        if Layer.NORMAL in layers:
            header[NORMAL_ATTRIBUTE] = files.normal_space.value
        write(temp(Path(path)), out.rgba, bit_depth, depth=depth, extra=extra,
              attributes=header)
        return
    if attributes:
        write(temp(Path(path)), out.rgba, bit_depth, attributes=attributes)
    else:
        write(temp(Path(path)), out.rgba, bit_depth)
    for layer in files.pictures(path):
        write(temp(picture_path(path, layer)), layer_picture(out, layer, files))
