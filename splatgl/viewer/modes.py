"""One frame of the viewer: which renderer call makes it, for each view mode.

Colour through the quad path draws straight into the quad renderer's own float target (no
readback: the window samples that texture).  Everything else comes back as a NumPy image from
the same :class:`~splatgl.api.Renderer` calls ``splatgl render`` makes: the tile path's
colour, the colourised expected depth (what ``--depth-png`` writes) and the |quad - tile| heat
map (what ``splatgl compare`` draws).
"""

from __future__ import annotations

import enum
import time
from dataclasses import dataclass
from typing import NamedTuple

import moderngl
import numpy as np

from ..cameras.camera import Camera
from ..imagefiles.pictures import depth_preview, heatmap
from ..api import Renderer
from ..gl.transfers import TransferCounts, transfers
from ..scene.splats import Scene
from ..scene.settings import RendererKind, RenderSettings
from ..cameras.view import View
from ..renderers.stereo import StereoLayout, StereoRenderer
from . import controls

#: Error that saturates the difference view's colour scale (8/255).
DIFFERENCE_SCALE = 8.0 / 255.0


class ViewMode(enum.Enum):
    COLOR = "colour"
    DEPTH = "depth"
    DIFFERENCE = "difference"


@dataclass
class FrameResult:
    """A rendered frame, ready to present.

    Exactly one of ``texture`` (the quad target: premultiplied ``(C, A)``, row 0 = top, owned
    by the renderer) and ``image`` ((H, W, 4) float32, background already composited) is set.
    ``sort`` and ``draw`` are seconds (see :class:`splatgl.viewer.overlay.Status`); ``splats``
    says how many splats took part (a phrase starting "splats"); ``note`` is extra status (the difference's maximum);
    ``quality`` says whether a budgeted frame is a draft or exact (:mod:`.pacing`).  A texture
    smaller than the window is a draft at a lower render scale: the display upscales it.
    """

    texture: moderngl.Texture | None
    image: np.ndarray | None
    premultiplied: bool
    sort: float
    draw: float
    splats: str
    note: str = ""
    quality: str = ""


class _Drawn(NamedTuple):
    splats: int
    transfers: TransferCounts | None
    device_order: bool


def splats_phrase(drawn, count: int, verb: str = "drawn") -> str:
    """The status panel's splats line for a frame drawn in the window (a
    :class:`~splatgl.interactive.draft.DraftFrame`, or alike): the splats drawn, or that the
    order stayed on the device, and what the frame moved between host and device."""
    head = (f"splats counted on the device / {count:,}" if drawn.device_order
            else f"splats {drawn.splats:,} {verb} / {count:,}")
    return head if drawn.transfers is None else f"{head}; {drawn.transfers.text()}"


def _times(renderer: Renderer, scene: Scene, settings: RenderSettings,
           kind: RendererKind) -> tuple[float, float, str]:
    """(sort, draw, splats text) of the last frame of ``kind`` from its ``last_times``
    (:class:`~splatgl.renderers.registry.StageTimes`)."""
    t = renderer.renderer_for(scene, settings, kind).last_times
    if t is None:
        return 0.0, 0.0, ""
    return t.ordering, t.drawing, t.summary(scene.count)


def render_frame(renderer: Renderer, scene: Scene, camera: Camera, settings: RenderSettings,
                 kind: RendererKind, view: ViewMode) -> FrameResult:
    """Render ``camera``'s view (world frame; the scene transform is applied here)."""
    if view is ViewMode.COLOR and kind is RendererKind.QUAD:
        quad = renderer.renderer_for(scene, settings, kind)
        frame = View.of(camera, settings, scene)
        before = transfers(renderer.ctx).snapshot()
        t0 = time.perf_counter()
        device = quad.device_order(frame) is not None   # the order stays on the device
        count = scene.count if device else len(quad.order(frame))  # cull + sort (draw() reuses it)
        t1 = time.perf_counter()
        target = quad.target(frame)
        quad.draw(frame, target)  # upload + draw, ends with a finish
        t2 = time.perf_counter()
        if device:
            t1 = t0 + quad.order_times.cull + quad.order_times.sort
        drawn = _Drawn(count, transfers(renderer.ctx).snapshot().since(before), device)
        return FrameResult(target.texture, None, True, t1 - t0, t2 - t1,
                           splats_phrase(drawn, scene.count, "visible"))
    if view is ViewMode.COLOR:
        rgba = renderer.render(scene, camera, settings, kind)
        return FrameResult(None, rgba, False, *_times(renderer, scene, settings, kind))
    if view is ViewMode.DEPTH:
        out = renderer.render_layers(scene, camera, settings, kind)
        img = depth_preview(out.expected_depth(), out.alpha)
        return FrameResult(None, img, False, *_times(renderer, scene, settings, kind))
    quad = renderer.render(scene, camera, settings, RendererKind.QUAD)
    tile = renderer.render(scene, camera, settings, RendererKind.TILE)
    worst = float(np.abs(quad[..., :3] - tile[..., :3]).max()) if quad.size else 0.0
    img = heatmap(quad, tile, DIFFERENCE_SCALE)
    sort, draw, splats = _times(renderer, scene, settings, RendererKind.QUAD)
    return FrameResult(None, img, False, sort, draw, splats,
                       f"max |quad - tile| {worst * 255:.1f}/255")


def render_stereo(renderer: Renderer, scene: Scene, camera: Camera, settings: RenderSettings,
                  kind: RendererKind, ipd: float) -> FrameResult:
    """Both eyes of ``camera`` side by side (interpupillary distance ``ipd``, world units),
    each eye the view fitted to half of ``camera``'s width; an odd width keeps one column of
    background on the right."""
    half = controls.fit_camera(camera, max(camera.width // 2, 1), camera.height)
    stereo = StereoRenderer(renderer, ipd, StereoLayout.SIDE_BY_SIDE)
    t0 = time.perf_counter()
    image = stereo.render(scene, half, settings, kind)
    if image.shape[1] < camera.width:   # an odd width: one column of background
        pad = np.zeros((image.shape[0], camera.width - image.shape[1], 4), np.float32)
        pad[..., :3] = settings.background
        image = np.concatenate([image, pad], axis=1)
    return FrameResult(None, image, False, 0.0, time.perf_counter() - t0,
                       f"splats {scene.count:,}, stereo IPD {ipd:g}")
