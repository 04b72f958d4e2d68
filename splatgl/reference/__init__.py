"""The NumPy per-tile reference rasterizer (3DGS forward pass, DESIGN.md sections 1-2).

Stages, each usable on its own::

    proj = project(scene, camera, settings, dtype, options)   # per-splat screen data + tile rects
    keys, values = emit_keys(proj)                              # (tile << 32 | depth bits, index)
    keys, values = sort(keys, values)                           # stable
    ranges = tile_ranges(keys, proj.n_tiles)                    # [start, end) per tile
    raster = rasterize(proj, values, ranges, background, options)  # options.order: global or per pixel

or all at once with :func:`render_reference`.  Never imports the OpenGL paths.
"""

from .binning import depth_bits, emit_keys, sort, tile_ranges
from ..constants import GSPLAT_ALPHA_MAX, GSPLAT_EXTENT_SIGMAS
from .options import Compat, ReferenceOptions
from .chunk import gaussian_alpha, gaussian_power
from .rasterize import Raster, rasterize, transmittance_trace
from .render import ReferenceImage, render_reference
from .stages import ProjectedSplats, gsplat_radius, gsplat_rect, inria_rect, project, tile_grid

__all__ = [
    "Compat", "ReferenceOptions", "GSPLAT_ALPHA_MAX", "GSPLAT_EXTENT_SIGMAS",
    "ProjectedSplats", "project", "tile_grid", "inria_rect", "gsplat_rect", "gsplat_radius",
    "emit_keys", "sort", "tile_ranges", "depth_bits",
    "Raster", "rasterize", "gaussian_power", "gaussian_alpha", "transmittance_trace",
    "ReferenceImage", "render_reference",
]
