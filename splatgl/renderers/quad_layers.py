"""The quad path's layers beyond colour and depth (splatgl/output/layers.py).

- normal: a further float target blended like colour in the same draw (NORMAL_OUTPUT: the
  fragment writes ``(n alpha, alpha)``, so the target's own alpha tracks the same
  transmittance and its rgb accumulates ``N = sum n alpha T``);
- median depth, count, top contributor: an ordered pass (:func:`draw_ordered`) that draws the
  same sorted quads again into two targets its fragment stage reads and writes through
  ``GL_EXT_shader_framebuffer_fetch`` (shaders/lib/ordered_layers.glsl), reproducing the
  reference's loop per pixel, early stop included, on the reference's tile rectangles
  (shaders/lib/tile_rect.glsl: the quad's faint fragments beyond them do not count); only when
  one of them is asked for;
- geometry under the splats (UNDER): the draws test each fragment against the geometry's depth
  texture; the colour is composited over the geometry on the CPU
  (:func:`splatgl.output.under.composite_under`).
"""

from __future__ import annotations

import dataclasses

import moderngl
import numpy as np

from ..cameras.view import View
from ..errors import SplatglError
from ..gl.targets import ColorTarget
from ..output.layers import ORDERED, Layer, RenderOutput
from ..output.under import UnderLayer, composite_depth, composite_under
from .early_stop import BatchHook, plain_bounds
from .quad_programs import FrameSwitches

#: The extension the ordered pass needs.
FETCH_EXTENSION = "GL_EXT_shader_framebuffer_fetch"


def composite(rgba: np.ndarray, background: tuple[float, float, float]) -> np.ndarray:
    """``C + (1 - A) bg`` on an (H, W, 4) premultiplied image; alpha is kept as A.

    Returns a new array.  Per channel and skipping zero channels: broadcasting over the
    (H, W, 3) view measured 5x slower (35 ms against 7 ms at 1280x720).
    """
    out = np.array(rgba, np.float32, copy=True)
    transmittance = None
    for c, value in enumerate(background):
        if value:
            if transmittance is None:
                transmittance = 1.0 - rgba[..., 3]
            out[..., c] += transmittance * np.float32(value)
    return out


def normal_location(layers: frozenset[Layer]) -> int:
    """The normal layer's attachment and fragment location (0: not asked for): after the
    colour and, when asked for, the depth attachment (:class:`~splatgl.gl.targets.ColorTarget`)."""
    return (2 if Layer.DEPTH in layers else 1) if Layer.NORMAL in layers else 0


def check_ordered(ctx: moderngl.Context, layers: frozenset[Layer]) -> None:
    """Refuse, in one line before any work, ordered layers on a driver without framebuffer fetch."""
    asked = sorted(layer.value for layer in layers & ORDERED)
    if asked and FETCH_EXTENSION not in ctx.extensions:
        raise SplatglError(f"the quad path's {', '.join(asked)} layers need the OpenGL extension "
                           f"{FETCH_EXTENSION}, which {ctx.info.get('GL_RENDERER', 'this driver')} "
                           "lacks; use --renderer tile or reference")


def draw_ordered(renderer, view: View, frame: FrameSwitches, count: int,
                 on_batch: BatchHook | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The ordered pass over the ``count`` sorted splats ``renderer`` (a
    :class:`~splatgl.renderers.quad.QuadRenderer`) has prepared and drawn; returns its state
    and ids targets read back ((H, W, 4) float32, (H, W, 4) uint32)."""
    ctx, gpu = renderer.ctx, renderer.gpu
    frame = dataclasses.replace(frame, batched=False, depth=False, normal=0, ordered=True)
    prog = renderer.programs.draw(view, frame)
    view.set_uniforms(prog)
    target = gpu.ordered_target(view.width, view.height)
    target.fbo.use()
    ctx.viewport = (0, 0, view.width, view.height)
    ctx.disable(moderngl.DEPTH_TEST | moderngl.CULL_FACE | moderngl.BLEND)
    target.clear()
    gpu.index.bind()                         # quad_light.vert reads the rows it draws
    bounds = plain_bounds(count)
    for start, end in zip(bounds[:-1], bounds[1:]):
        if end > start:
            gpu.draw_range(prog, start, end - start, blend=False)
        if on_batch is not None:
            ctx.finish()
            on_batch(end, count)
    ctx.finish()
    return target.read()


def layer_output(target: ColorTarget, rgba: np.ndarray, layers: frozenset[Layer],
                 ordered: tuple[np.ndarray, np.ndarray] | None, under: UnderLayer | None,
                 background) -> RenderOutput:
    """The frame's :class:`RenderOutput` from the premultiplied ``rgba`` read back, the target's
    further attachments and the ordered pass's targets (if it ran)."""
    depth = target.read_depth() if Layer.DEPTH in layers else np.zeros(rgba.shape[:2], np.float32)
    planes: dict[str, np.ndarray] = {}
    if Layer.NORMAL in layers:
        planes["normal"] = target.read_normal()
    if ordered is not None:
        f, u = ordered
        if Layer.MEDIAN_DEPTH in layers:
            planes["median_depth"] = np.ascontiguousarray(f[..., 1])
        if Layer.COUNT in layers:
            planes["count"] = np.ascontiguousarray(u[..., 0])
        if Layer.TOP_ID in layers:
            planes["top_id"] = u[..., 1].astype(np.int64) - 1
    if under is None:
        return RenderOutput(composite(rgba, background), depth, layers, **planes)
    if Layer.DEPTH in layers:
        depth = composite_depth(depth, rgba[..., 3], under)
    return RenderOutput(composite_under(rgba[..., :3], rgba[..., 3], under, background), depth,
                        layers, **planes)
