"""The quad path's device-resident order (``--sort gpu``; issue 40 item 1).

Per view, with nothing per splat crossing the bus:

1. ``shaders/order_cull.comp``, one invocation per splat: the cull of
   :func:`splatgl.order.cull.cull_visible` (same float32 operations, so the same depth bits and
   plane decisions; the peak-alpha bound in float32 with a band of
   :data:`~splatgl.constants.DEVICE_CULL_BAND` that only ever keeps more) writes key i = the
   float bits of z (0xFFFFFFFF when culled) and value i = i into the radix sorter's A buffers,
   and adds the kept count into the indirect draw command's instance count (one atomic per
   work group);
2. :meth:`splatgl.gl.radix_sort.RadixSorter.sort_buffers` sorts all N keys on the device (the
   pass plan read from the keys there): stable, so the kept splats come first ordered by
   (z, index), exactly :class:`splatgl.order.stage.SceneOrder`'s order;
3. the draw reads its instance count from the command (``glDrawArraysInstancedIndirect``) and
   its splats from the sorted values (the vertex stage's instanced ``splat_index``, or the
   pre-pass's ``order``, which runs over all N slots: the host never learns the count).

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
from ..gl.bindings import (ORDER_BINDING_COMMAND, ORDER_BINDING_CULL, ORDER_BINDING_KEYS,
                           ORDER_BINDING_VALUES, ORDER_GROUP)
from ..gl.radix_sort import RadixSorter
from ..gl.shaders import ProgramCache
from ..gl.transfers import transfers
from ..model.scene import Scene
from ..order.cull import CullData, plane_constants

#: Bytes of the indirect draw command (count, instance count, first, base instance).
COMMAND_BYTES = 16


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
        rows = cull_rows(CullData.from_scene(scene)).tobytes()
        self._cull = ctx.buffer(rows)       # the one-time upload (not a per-frame transfer)
        self._command = ctx.buffer(reserve=COMMAND_BYTES)
        self._prog = programs.compute("order_cull.comp")
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
        """The indirect draw command (vertices, kept count, 0, 0)."""
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
        prog = self._prog
        self._set_uniforms(prog, view, antialias)
        counter.uniforms(prog)
        keys, values = self.sorter.buffers()
        self._cull.bind_to_storage_buffer(ORDER_BINDING_CULL)
        keys.bind_to_storage_buffer(ORDER_BINDING_KEYS)
        values.bind_to_storage_buffer(ORDER_BINDING_VALUES)
        self._command.bind_to_storage_buffer(ORDER_BINDING_COMMAND)
        prog.run(group_x=-(-self.count // ORDER_GROUP))
        self.ctx.memory_barrier()
        t1 = time.perf_counter()
        if self.count >= 2:
            self.sorter.sort_buffers(self.count)
            counter.upload(4)                          # the sort's key count
            for sort_prog in self.sorter._progs.values():   # and its programs' uniforms
                counter.uniforms(sort_prog)
        self._state = state
        return t1 - t0, time.perf_counter() - t1

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
        self._cull.release()
        self._command.release()
        self.sorter.release()
