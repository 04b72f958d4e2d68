"""The quad path's device-resident order (``--sort gpu``; issue 40 item 1).

Per view, with nothing per splat crossing the bus:

1. ``shaders/order_cull.comp``, one invocation per splat: the view's cull
   (:data:`splatgl.order.stage.CULLS`), one twin per cull kind with the same float32
   operations in the same order (``precise``), so the same depth bits and decisions: the side
   planes of :func:`splatgl.order.cull.cull_visible` (pinhole, OpenCV; the peak-alpha bound's
   float32 decision :func:`splatgl.order.cull.peak_keeps`, exactly rounded operations only:
   the CPU's kept splats, so early termination's batch bounds are the CPU's), its orthographic box (``CULL_BOX``), and the lens cameras' distance, fisheye cone
   and equirectangular seam copies of :func:`splatgl.order.lens_cull.lens_keys`
   (``CULL_SPHERE``; a panorama runs a second invocation per splat for its seam copy, whose
   index carries :data:`~splatgl.cameras.equirect.WRAP_FLAG`).  It stages key j = the float
   bits of z (of the distance; 0xFFFFFFFF when culled) and counts each work group's kept ones;
2. ``order_scan.comp`` (one work group) turns the counts into each group's first slot and
   writes the total into the indirect draw command (and the pre-pass's dispatch size);
   ``order_compact.comp`` writes the kept keys with their indices, in slot order, into the
   radix sorter's A buffers (an ordered stream compaction);
3. :meth:`splatgl.gl.radix_sort.RadixSorter.sort_buffers` sorts that many keys (its count
   copied from the command on the device): stable, so the kept splats come ordered by
   (depth, index), exactly :class:`splatgl.order.stage.SceneOrder`'s order;
4. the draw reads its instance count from the command (``glDrawArraysInstancedIndirect``) and
   its splats from the sorted values (the vertex stage's instanced ``splat_index``), or the
   pre-pass (``DEVICE_COUNT``) is dispatched from the command's second half and prepares that
   many slots: the host never learns the count.

Per frame the host writes the 16-byte command (its vertex count, a zero instance count) and the
programs' uniforms; the scene's cull data (:class:`~splatgl.order.cull.CullData`, 32 bytes a
splat) is uploaded once.  Views this order does not cover (:meth:`DeviceOrder.covers`:
omni-directional stereo, whose eye offsets need transcendentals no device reproduces bit for
bit, the cull off, a level-of-detail cut, the ordered layers) take the CPU cull with the device
sort instead.  Early termination runs with this order through
:mod:`~splatgl.renderers.early_stop_device` (its decisions made on the device).
"""

from __future__ import annotations

import time

import moderngl
import numpy as np

from ..cameras.equirect import SEAM_MARGIN_PX
from ..cameras.model import CullKind
from ..cameras.view import View
from ..gl.bindings import (BINDING_DEVICE_COUNT, ORDER_BINDING_BLOCKS, ORDER_BINDING_COMMAND, ORDER_BINDING_CULL,
                           ORDER_BINDING_KEYS, ORDER_BINDING_STAGED, ORDER_BINDING_VALUES,
                           ORDER_GROUP)
from ..gl import dispatch, limits
from ..gl.radix_sort import RadixSorter
from ..gl.shaders import ProgramCache
from ..gl.transfers import transfers
from ..scene.splats import Scene
from ..order.cull import AA_LOG_FLOOR, CullData, peak_constants32, plane_constants

#: Bytes of the indirect draw command (count, instance count, first, base instance), then the
#: pre-pass's indirect dispatch size (x, y, z, unused) at :data:`PREPASS_ARGS`.
COMMAND_BYTES = 32
PREPASS_ARGS = 16


def cull_rows(data: CullData) -> np.ndarray:
    """(N, 8) float32 rows of order_cull.comp's cull buffer: x, y, z, radius, max_scale,
    log(255 opacity) (:attr:`CullData.cut_log`, the peak bound's level), alive, faint."""
    rows = np.empty((data.count, 8), np.float32)
    rows[:, :3] = data.xyz.T
    rows[:, 3] = data.radius
    rows[:, 4] = data.max_scale
    rows[:, 5] = data.cut_log
    rows[:, 6] = data.alive
    rows[:, 7] = data.faint
    return rows


class DeviceOrder:
    """The device-resident order of one scene (see the module doc); :meth:`release` after use
    (it releases ``sorter``, which it owns: nothing else may sort in its buffers)."""

    def __init__(self, ctx: moderngl.Context, scene: Scene, programs: ProgramCache,
                 sorter: RadixSorter):
        self.ctx, self.sorter, self.programs = ctx, sorter, programs
        self.count = scene.count
        limits.check_splat_buffer(ctx, self.count, 32 * self.count, "the device order's cull "
                                  "rows, 32 bytes a splat", advice=limits.DERIVED_ADVICE)
        rows = cull_rows(CullData.from_scene(scene)).tobytes()
        self._cull = ctx.buffer(rows)       # the one-time upload (not a per-frame transfer)
        self._command = ctx.buffer(reserve=COMMAND_BYTES)
        self._slots = 0                     # staged slots the buffers hold (_reserve)
        #: The most splats the last view can draw: the scene's, twice for a panorama (copies).
        self.slots = self.count
        self._staged = self._blocks = None
        self._progs = {name: programs.compute(f"order_{name}.comp") for name in ("scan", "compact")}
        self._state: tuple | None = None    # (view key, vertices) of the order on the device
        self._reserve(self.count)

    def _reserve(self, slots: int) -> None:
        """Room for ``slots`` staged keys (a panorama stages 2 per splat: its seam copies)."""
        if slots <= self._slots:
            return
        for buf in (self._staged, self._blocks):
            if buf is not None:
                buf.release()
        self._staged = self.ctx.buffer(reserve=4 * max(slots, 1))
        self._blocks = self.ctx.buffer(reserve=4 * self._groups(slots))
        self.sorter.reserve(max(slots, 2))
        self._slots = slots

    @staticmethod
    def _groups(slots: int) -> int:
        return max(1, -(-slots // ORDER_GROUP))

    @staticmethod
    def covers(view: View) -> bool:
        """Whether order_cull.comp has the view's cull: every camera model's but an
        omni-directional stereo panorama's (see the module doc)."""
        return not getattr(view.model, "ods_eye", 0.0)

    @staticmethod
    def cull_defines(view: View) -> dict[str, object]:
        """order_cull.comp's switches for ``view``'s cull kind (its twin, see the shader)."""
        frustum = view.frustum
        if frustum.kind is CullKind.BOX:
            return {"CULL_BOX": 1}
        if frustum.kind is CullKind.SPHERE:
            cam = frustum.camera
            return {"CULL_SPHERE": 1,
                    **({"CULL_FISHEYE": 1} if cam.model.angle_limit(cam) is not None else {}),
                    **({"CULL_SEAM": 1} if cam.model.seam_period(cam) is not None else {})}
        return {}

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
        defines = self.cull_defines(view)
        slots = 2 * self.count if "CULL_SEAM" in defines else self.count
        self._reserve(slots)
        self.slots = slots
        groups = self._groups(slots)
        counter = transfers(self.ctx)
        counter.write(self._command, np.array([vertices, 0, 0, 0], np.uint32).tobytes())
        cull = self.programs.compute("order_cull.comp", defines)
        scan, compact = self._progs["scan"], self._progs["compact"]
        self._set_uniforms(cull, view, antialias, slots)
        scan["u_blocks"].value = groups
        compact["u_count"].value = slots
        compact["u_rows"].value = self.count
        for prog in (cull, scan, compact):
            counter.uniforms(prog)
        keys, values = self.sorter.buffers()
        for buf, binding in ((self._cull, ORDER_BINDING_CULL), (self._staged, ORDER_BINDING_STAGED),
                             (self._blocks, ORDER_BINDING_BLOCKS),
                             (self._command, ORDER_BINDING_COMMAND), (keys, ORDER_BINDING_KEYS),
                             (values, ORDER_BINDING_VALUES)):
            buf.bind_to_storage_buffer(binding)
        what = f"{slots} splat slots"
        dispatch.run(cull, groups, what)
        self.ctx.memory_barrier()
        dispatch.set_limit(scan)
        scan.run(group_x=1)
        self.ctx.memory_barrier()
        dispatch.run(compact, groups, what)
        self.ctx.memory_barrier()
        t1 = time.perf_counter()
        self.sorter.sort_buffers(slots, device_count=(self._command, 4))
        for sort_prog in self.sorter._progs.values():   # the sort's uniforms
            counter.uniforms(sort_prog)
        self._state = state
        return t1 - t0, time.perf_counter() - t1

    def run_prepass(self, comp: moderngl.ComputeShader) -> None:
        """Dispatch ``comp`` (quad_prepass.comp with DEVICE_COUNT, uniforms set, buffers bound)
        over the kept slots, sized from the command on the device."""
        self._command.bind_to_storage_buffer(BINDING_DEVICE_COUNT)
        comp["u_first"].value = 0
        dispatch.run_indirect(comp, self._command, PREPASS_ARGS, 0, "", split=True)
        self.ctx.memory_barrier()

    def _set_uniforms(self, prog: moderngl.ComputeShader, view: View, antialias: bool,
                      slots: int) -> None:
        frustum = view.frustum
        cam = frustum.camera
        r = np.asarray(cam.rotation, np.float32)
        t = np.asarray(cam.translation, np.float32)
        values = {
            "u_count": self.count, "u_slots": slots, "u_r0": tuple(r[0]), "u_r1": tuple(r[1]),
            "u_r2": tuple(r[2]), "u_t": tuple(t), "u_near": float(view.near32),
            "u_peak": frustum.peak, "u_antialias": antialias, "u_scale": float(view.scale),
            "u_focal": (cam.fx, cam.fy, cam.cx, cam.cy),
        }
        if frustum.kind is CullKind.SPHERE:   # lens_keys' constants
            limit = cam.model.angle_limit(cam)
            values["u_near"] = float(np.float32(view.near))
            values["u_lens"] = (float(np.float32(np.cos(limit))) if limit is not None else 0.0,
                                float(np.float32(view.scale)),
                                float(np.float32(SEAM_MARGIN_PX / cam.fx)))
        else:
            planes = plane_constants(frustum, view.scale)
            peak = peak_constants32(cam)    # peak_keeps' float32 constants
            values.update({"u_plane_x": tuple(planes[0, :4]), "u_plane_y": tuple(planes[1, :4]),
                           "u_inside": (planes[0, 4], planes[0, 5], planes[1, 4], planes[1, 5]),
                           "u_focal": tuple(map(float, peak[:4])),
                           "u_image": tuple(map(float, peak[4:])),
                           "u_aa_floor": float(AA_LOG_FLOOR)})
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
