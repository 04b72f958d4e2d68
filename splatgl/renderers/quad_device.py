"""The quad path's device-resident order (``--sort gpu``; issue 40 item 1).

Per view, with nothing per splat crossing the bus:

1. ``shaders/order_cull.comp``, one invocation per splat: the cull of
   :func:`splatgl.order.cull.cull_visible` (same float32 operations, so the same depth bits and
   plane decisions; the peak-alpha bound in float32 with a band of
   :data:`~splatgl.constants.DEVICE_CULL_BAND` that only ever keeps more) stages key i = the
   float bits of z (0xFFFFFFFF when culled) and counts each work group's kept splats;
2. ``order_scan.comp`` (one work group) turns the counts into each group's first slot and
   writes the total into the indirect draw command (and the pre-pass's dispatch size);
   ``order_compact.comp`` writes the kept keys with their indices, in index order, into the
   radix sorter's A buffers (an ordered stream compaction);
3. :meth:`splatgl.gl.radix_sort.RadixSorter.sort_buffers` sorts that many keys (its count
   copied from the command on the device): stable, so the kept splats come ordered by
   (z, index), exactly :class:`splatgl.order.stage.SceneOrder`'s order;
4. the draw reads its instance count from the command (``glDrawArraysInstancedIndirect``) and
   its splats from the sorted values (the vertex stage's instanced ``splat_index``), or the
   pre-pass (``DEVICE_COUNT``) is dispatched from the command's second half and prepares that
   many slots: the host never learns the count.

Per frame the host writes the 16-byte command (its vertex count, a zero instance count) and the
programs' uniforms; the scene's cull data (:class:`~splatgl.order.cull.CullData`, 32 bytes a
splat) is uploaded once.  Views this order does not cover (:meth:`DeviceOrder.covers`: lens
cameras' spheres, orthographic boxes, the cull off, a level-of-detail cut, the ordered layers)
take the CPU cull with the device sort instead.
"""

from __future__ import annotations

import time

import moderngl
import numpy as np

from ..cameras.model import CullKind
from ..cameras.view import View
from ..gl.bindings import (BINDING_DEVICE_COUNT, ORDER_BINDING_BLOCKS, ORDER_BINDING_COMMAND, ORDER_BINDING_CULL,
                           ORDER_BINDING_KEYS, ORDER_BINDING_STAGED, ORDER_BINDING_VALUES,
                           ORDER_GROUP)
from ..gl import limits
from ..gl.radix_sort import RadixSorter
from ..gl.shaders import ProgramCache
from ..gl.transfers import transfers
from ..scene.splats import Scene
from ..order.cull import CullData, plane_constants

#: Bytes of the indirect draw command (count, instance count, first, base instance), then the
#: pre-pass's indirect dispatch size (x, y, z, unused) at :data:`PREPASS_ARGS`.
COMMAND_BYTES = 32
PREPASS_ARGS = 16


def cull_rows(data: CullData) -> np.ndarray:
    """(N, 8) float32 rows of order_cull.comp's cull buffer: x, y, z, radius, max_scale,
    opacity, alive, faint."""
    rows = np.empty((data.count, 8), np.float32)
    rows[:, :3] = data.xyz.T
    rows[:, 3] = data.radius
    rows[:, 4] = data.max_scale
    rows[:, 5] = data.opacities
    rows[:, 6] = data.alive
    rows[:, 7] = data.faint
    return rows


class DeviceOrder:
    """The device-resident order of one scene (see the module doc); :meth:`release` after use
    (it releases ``sorter``, which it owns: nothing else may sort in its buffers)."""

    def __init__(self, ctx: moderngl.Context, scene: Scene, programs: ProgramCache,
                 sorter: RadixSorter):
        self.ctx, self.sorter = ctx, sorter
        self.count = scene.count
        limits.check_splat_buffer(ctx, self.count, 32 * self.count, "the device order's cull "
                                  "rows, 32 bytes a splat", advice=limits.DERIVED_ADVICE)
        rows = cull_rows(CullData.from_scene(scene)).tobytes()
        self._cull = ctx.buffer(rows)       # the one-time upload (not a per-frame transfer)
        self._command = ctx.buffer(reserve=COMMAND_BYTES)
        self._groups = max(1, -(-self.count // ORDER_GROUP))
        self._staged = ctx.buffer(reserve=4 * max(self.count, 1))
        self._blocks = ctx.buffer(reserve=4 * self._groups)
        self._progs = {name: programs.compute(f"order_{name}.comp")
                       for name in ("cull", "scan", "compact")}
        self._state: tuple | None = None    # (view key, vertices) of the order on the device
        sorter.reserve(max(self.count, 2))

    @staticmethod
    def covers(view: View) -> bool:
        """Whether order_cull.comp is the view's cull: the side planes of a perspective image."""
        frustum = view.frustum
        return frustum.kind is CullKind.FRUSTUM and not frustum.camera.is_orthographic

    @property
    def values(self) -> moderngl.Buffer:
        """The sorted splat indices (the first ``instance count`` are drawn)."""
        return self.sorter.buffers()[1]

    @property
    def command(self) -> moderngl.Buffer:
        """The indirect draw command (vertices, kept count, 0, 0), then the pre-pass's
        dispatch size at :data:`PREPASS_ARGS`."""
        return self._command

    def run(self, view: View, vertices: int, antialias: bool) -> tuple[float, float]:
        """Cull, key and sort for ``view`` on the device (nothing when the view and the vertex
        count repeat: the order is still there); returns the seconds spent issuing the cull
        and the sort (no wait for the device)."""
        state = (view.key, vertices, antialias, view.scale)
        if state == self._state:
            return 0.0, 0.0
        t0 = time.perf_counter()
        counter = transfers(self.ctx)
        counter.write(self._command, np.array([vertices, 0, 0, 0], np.uint32).tobytes())
        cull, scan, compact = (self._progs[name] for name in ("cull", "scan", "compact"))
        self._set_uniforms(cull, view, antialias)
        scan["u_blocks"].value = self._groups
        compact["u_count"].value = self.count
        for prog in (cull, scan, compact):
            counter.uniforms(prog)
        keys, values = self.sorter.buffers()
        for buf, binding in ((self._cull, ORDER_BINDING_CULL), (self._staged, ORDER_BINDING_STAGED),
                             (self._blocks, ORDER_BINDING_BLOCKS),
                             (self._command, ORDER_BINDING_COMMAND), (keys, ORDER_BINDING_KEYS),
                             (values, ORDER_BINDING_VALUES)):
            buf.bind_to_storage_buffer(binding)
        cull.run(group_x=self._groups)
        self.ctx.memory_barrier()
        scan.run(group_x=1)
        self.ctx.memory_barrier()
        compact.run(group_x=self._groups)
        self.ctx.memory_barrier()
        t1 = time.perf_counter()
        self.sorter.sort_buffers(self.count, device_count=(self._command, 4))
        for sort_prog in self.sorter._progs.values():   # the sort's uniforms
            counter.uniforms(sort_prog)
        self._state = state
        return t1 - t0, time.perf_counter() - t1

    def run_prepass(self, comp: moderngl.ComputeShader) -> None:
        """Dispatch ``comp`` (quad_prepass.comp with DEVICE_COUNT, uniforms set, buffers bound)
        over the kept slots, sized from the command on the device."""
        self._command.bind_to_storage_buffer(BINDING_DEVICE_COUNT)
        comp["u_first"].value = 0
        comp.run_indirect(self._command, PREPASS_ARGS)
        self.ctx.memory_barrier()

    def _set_uniforms(self, prog: moderngl.ComputeShader, view: View, antialias: bool) -> None:
        frustum = view.frustum
        cam = frustum.camera
        r = np.asarray(cam.rotation, np.float32)
        t = np.asarray(cam.translation, np.float32)
        planes = plane_constants(frustum, view.scale)
        tx, ty = cam.tan_half_fov
        values = {
            "u_count": self.count, "u_r0": tuple(r[0]), "u_r1": tuple(r[1]), "u_r2": tuple(r[2]),
            "u_t": tuple(t), "u_near": float(view.near32), "u_plane_x": tuple(planes[0, :4]),
            "u_plane_y": tuple(planes[1, :4]),
            "u_inside": (planes[0, 4], planes[0, 5], planes[1, 4], planes[1, 5]),
            "u_peak": frustum.peak, "u_antialias": antialias, "u_scale": float(view.scale),
            "u_focal": (cam.fx, cam.fy, cam.cx, cam.cy),
            "u_image": (cam.width, cam.height, tx, ty),
        }
        for name, value in values.items():
            if name in prog:
                prog[name].value = value

    def kept(self) -> int:
        """The kept count, read back (for tests: a synchronisation point and 4 bytes)."""
        return int(np.frombuffer(self._command.read(4, offset=4), np.uint32)[0])

    def order(self) -> np.ndarray:
        """The drawn order, read back (for tests)."""
        n = self.kept()
        return np.frombuffer(self.values.read(4 * n), np.uint32).copy() if n else \
            np.zeros(0, np.uint32)

    def release(self) -> None:
        """Release its buffers and its sorter."""
        for buf in (self._cull, self._command, self._staged, self._blocks):
            buf.release()
        self.sorter.release()
