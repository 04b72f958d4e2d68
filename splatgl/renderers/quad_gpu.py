"""The quad path's GL resources: per-view buffers, vertex arrays, the blend target.

The scene's own storage buffers are uploaded once (:class:`~splatgl.gl.scene_buffers.
SceneBuffers`); per view only the sorted rows (and a level-of-detail cut's per-slot opacity
weights) are written, into buffers that grow as needed and are reused.
"""

from __future__ import annotations

from typing import Callable

import moderngl
import numpy as np

from ..gl.bindings import (BINDING_OPACITY_WEIGHT, BINDING_ORDER, BINDING_PREPARED,
                           BINDING_PREPARED_NORMAL, BINDING_PREPARED_RADIUS, PREPASS_GROUP,
                           UNDER_UNIT)
from ..gl import dispatch as groups_dispatch
from ..gl.buffers import GrowableBuffer
from ..gl.transfers import transfers
from ..gl.targets import ColorTarget, OrderedTarget
from ..scene.settings import Precision
from .early_stop import COMMAND_BYTES

#: Bytes per splat of the pre-pass output (4 vec4, see shaders/quad_prepass.comp).
PREPARED_BYTES = 64


class QuadResources:
    """The per-view GL objects of one quad renderer (see the module doc).

    ``uses_prepass``: whether the draw reads the pre-pass's prepared quads (instance k of a
    range reads ``prepared[u_base + k]``) instead of the sorted indices.  ``triangles``: plain
    draws emit one triangle per splat (3 vertices, the TRIANGLE_PER_SPLAT shader switch set by
    :meth:`~splatgl.renderers.quad.QuadRenderer.use_triangles`) instead of a 4-vertex strip.
    """

    def __init__(self, ctx: moderngl.Context, uses_prepass: bool):
        self.ctx, self.uses_prepass = ctx, uses_prepass
        self.triangles = False
        self.index = GrowableBuffer(ctx, BINDING_ORDER, minimum=4, stride=4,
                                    what="the sorted splat indices, 4 bytes a splat")
        self.weights = GrowableBuffer(ctx, BINDING_OPACITY_WEIGHT, minimum=4, stride=4,
                                      what="the cut's opacity weights, 4 bytes a splat")
        self.prepared, self.prepared_normal, self.prepared_radius = (   # limits: one line each
            GrowableBuffer(ctx, binding, what=f"the pre-pass's {name}, {stride} bytes a splat",
                           stride=stride)
            for binding, name, stride in ((BINDING_PREPARED, "prepared quads", PREPARED_BYTES),
                                          (BINDING_PREPARED_NORMAL, "normals", 16),
                                          (BINDING_PREPARED_RADIUS, "radii", 4)))
        self._target: ColorTarget | None = None
        self._ordered: OrderedTarget | None = None
        self._under: moderngl.Texture | None = None
        self._vaos: dict[tuple, tuple[moderngl.VertexArray, moderngl.Program, object]] = {}
        self._plain_command: moderngl.Buffer | None = None

    def upload(self, order: np.ndarray, weights: np.ndarray | None) -> None:
        """Write the sorted rows, and the cut's opacity weights (one float per slot) if any."""
        self.index.upload(order.tobytes())
        if self.index.grew:
            self._release_vaos()  # they read the old buffer
        if weights is not None:
            self.weights.upload(weights.tobytes())

    def run_prepass(self, comp: moderngl.ComputeShader, count: int, weighted: bool,
                    normals: bool = False, radii: bool = False, chunk: int | None = None,
                    between: Callable[[], None] | None = None,
                    order: moderngl.Buffer | None = None,
                    dispatch: Callable[[moderngl.ComputeShader], None] | None = None) -> None:
        """Run ``comp`` (quad_prepass.comp, uniforms set) over the ``count`` sorted splats into
        the prepared buffer (with ``normals`` the normal layer's buffer, with ``radii`` the
        ordered pass's).  With ``between``, the pass runs in chunks of ``chunk`` slots and
        ``between()`` is called after each but the last, to a finish (it may raise to abandon
        the frame: a million splats' pre-pass takes about half a second on llvmpipe).
        ``order``: the sorted indices' buffer where it is not :attr:`index` (the device-resident
        order's, :mod:`~splatgl.renderers.quad_device`); ``dispatch(comp)`` then runs it (its
        size read from the device; ``count`` is the most slots there can be)."""
        self.prepared.ensure(count * PREPARED_BYTES).bind_to_storage_buffer(BINDING_PREPARED)
        if normals:
            self.prepared_normal.ensure(count * 16).bind_to_storage_buffer(BINDING_PREPARED_NORMAL)
        if radii:
            self.prepared_radius.ensure(count * 4).bind_to_storage_buffer(BINDING_PREPARED_RADIUS)
        if count == 0:
            return
        if weighted:
            self.weights.bind()
        if "u_count" in comp:    # (the DEVICE_COUNT variant reads its count on the device)
            comp["u_count"].value = count
        if order is None:
            self.index.bind()
        else:
            order.bind_to_storage_buffer(BINDING_ORDER)
        if dispatch is not None:
            dispatch(comp)
            return
        step = count if between is None or not chunk else max(PREPASS_GROUP, int(chunk))
        for first in range(0, count, step):
            comp["u_first"].value = first
            groups_dispatch.run(comp, (min(step, count - first) + PREPASS_GROUP - 1)
                                // PREPASS_GROUP, f"{count} splats")
            if between is not None and first + step < count:
                self.ctx.finish()
                between()
        self.ctx.memory_barrier()

    def target(self, width: int, height: int, precision: Precision, depth: bool,
               stop_mask: bool, normal: bool = False) -> ColorTarget:
        """The blend target of this size and kind (re-made when either changes)."""
        t = self._target
        if (t is None or t.size != (width, height) or t.precision is not precision
                or t.has_depth != depth or t.has_stop_mask != stop_mask or t.has_normal != normal):
            if t is not None:
                t.release()
            self._target = ColorTarget(self.ctx, width, height, precision, depth,
                                       stop_mask=stop_mask, normal=normal)
        return self._target

    def ordered_target(self, width: int, height: int) -> OrderedTarget:
        """The ordered pass's targets of this size (re-made when it changes)."""
        if self._ordered is None or self._ordered.size != (width, height):
            if self._ordered is not None:
                self._ordered.release()
            self._ordered = OrderedTarget(self.ctx, width, height)
        return self._ordered

    def bind_under(self, depth: np.ndarray) -> None:
        """Upload the geometry depth (H, W) float32 (row 0 at the top, like the target) and bind
        it at UNDER_UNIT for the draw's fragment test."""
        h, w = depth.shape
        if self._under is None or self._under.size != (w, h):
            if self._under is not None:
                self._under.release()
            self._under = self.ctx.texture((w, h), 1, dtype="f4")
            self._under.filter = moderngl.NEAREST, moderngl.NEAREST
        transfers(self.ctx).write(self._under, np.ascontiguousarray(depth, np.float32).tobytes())
        self._under.use(UNDER_UNIT)

    def vertex_array(self, prog: moderngl.Program, source: moderngl.Buffer | None) -> moderngl.VertexArray:
        """The VAO drawing ``prog`` with its per-instance attribute read from ``source``: the
        sorted indices, the occlusion cull's survivors, or none (the pre-pass's instance k
        reads prepared[u_base + k])."""
        attribute = "splat_slot" if self.uses_prepass else "splat_index"
        key = (prog.glo, None if source is None else source.glo)
        cached = self._vaos.get(key)
        # GL names are reused: a buffer that grew (released, made anew) can come back under its
        # old name, and a vertex array of the released buffer must not draw it (NVIDIA's driver
        # crashed in render_indirect).  So the objects themselves are kept and compared.
        if cached is not None and (cached[1] is not prog or cached[2] is not source):
            cached[0].release()
            cached = None
        if cached is None:
            content = [] if source is None else [(source, "u4/i", attribute)]
            cached = self._vaos[key] = (self.ctx.vertex_array(prog, content), prog, source)
        return cached[0]

    def draw_range(self, prog: moderngl.Program, start: int, n: int, blend: bool = True) -> None:
        """Draw sorted slots [start, start + n) without early termination (``blend`` False: the
        ordered pass, whose fragment stage writes its targets itself)."""
        if blend:
            self.ctx.enable(moderngl.BLEND)
        else:
            self.ctx.disable(moderngl.BLEND)
        mode, vertices = ((moderngl.TRIANGLES, 3) if self.triangles
                          else (moderngl.TRIANGLE_STRIP, 4))
        if self.uses_prepass:
            prog["u_base"].value = start
            self.vertex_array(prog, None).render(mode, vertices=vertices, instances=n)
            return
        vao = self.vertex_array(prog, self.index.buf)
        if start == 0:
            vao.render(mode, vertices=vertices, instances=n)
            return
        # A later range: the instanced attribute starts at baseInstance (an indirect command).
        if self._plain_command is None:
            self._plain_command = self.ctx.buffer(reserve=COMMAND_BYTES)
        transfers(self.ctx).write(self._plain_command,
                                  np.array([vertices, n, 0, start, 0], np.uint32).tobytes())
        vao.render_indirect(self._plain_command, mode, count=1)

    def draw_indirect(self, prog: moderngl.Program, order: moderngl.Buffer,
                      command: moderngl.Buffer) -> None:
        """One draw of the sorted slots whose count ``command`` holds on the device (the
        device-resident order): instance k reads ``order[k]`` (or the pre-pass's slot k)."""
        self.ctx.enable(moderngl.BLEND)
        mode = moderngl.TRIANGLES if self.triangles else moderngl.TRIANGLE_STRIP
        if self.uses_prepass:
            prog["u_base"].value = 0
        self.vertex_array(prog, None if self.uses_prepass else order).render_indirect(
            command, mode, count=1)

    def _release_vaos(self) -> None:
        for vao, _, _ in self._vaos.values():
            vao.release()
        self._vaos.clear()

    def release(self) -> None:
        self._release_vaos()
        for buf in (self.index, self.weights, self.prepared, self.prepared_normal,
                    self.prepared_radius):
            buf.release()
        for obj in (self._target, self._ordered, self._plain_command, self._under):
            if obj is not None:
                obj.release()
        self._target = self._ordered = self._plain_command = self._under = None
