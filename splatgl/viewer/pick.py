"""The viewer's Ctrl+click: the splats of the pixel under the cursor, front to back, from the
reference (:func:`splatgl.reference.pixel.pixel_splats`, what ``splatgl pixel`` prints)."""

from __future__ import annotations

import math

import glfw

from ..errors import SplatglError
from ..reference.pixel import PixelListing, pixel_splats

#: Splats printed per click (the status line names the top one).
PRINTED = 20


def window_pixel(x: float, y: float, window: tuple[int, int], size: tuple[int, int]
                 ) -> tuple[int, int] | None:
    """The image pixel (column, row) under window point (``x``, ``y``) of a window of
    ``window`` points showing an image of ``size`` pixels (HiDPI: more pixels than points), or
    None outside it."""
    col = math.floor(x * size[0] / max(window[0], 1))
    row = math.floor(y * size[1] / max(window[1], 1))
    return (col, row) if 0 <= col < size[0] and 0 <= row < size[1] else None


def list_pixel(viewer, x: float, y: float) -> PixelListing | None:
    """Print the listing of the pixel under (``x``, ``y``) of ``viewer``'s window and sum it up
    on its status line; None (and a status line saying why) where there is none to list."""
    viewer.need_present = True
    if viewer.options.stereo is not None:
        viewer.message = "pixel listing: not in the stereo view (one eye per pixel)"
        return None
    camera = viewer.camera()
    pixel = window_pixel(x, y, glfw.get_window_size(viewer.window), (camera.width, camera.height))
    if pixel is None:
        return None
    try:
        listing = pixel_splats(viewer.scene, camera, *pixel, viewer.settings,
                               viewer.settings.convention)
    except SplatglError as exc:          # a camera the reference cannot draw for this scene
        viewer.message = f"pixel listing: {exc}"
        return None
    viewer.display.marker = (pixel, (viewer.state, viewer.size))   # until the view changes
    print(listing.table(PRINTED), flush=True)
    top = max(listing.splats, key=lambda s: s.weight, default=None)
    viewer.message = (f"pixel {pixel}: {len(listing.splats)} splats, alpha {listing.alpha:.3f}"
                      + (f", top splat {top.index} (weight {top.weight:.3f})" if top else ""))
    return listing
