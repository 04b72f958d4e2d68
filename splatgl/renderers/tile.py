"""The per-tile GPU renderer: the 3DGS rasterizer's stages in OpenGL 4.3 compute shaders.

Stages (DESIGN.md section 2; each GPU stage has one shader and a same-named NumPy twin in
:mod:`splatgl.reference`):

1. ``project`` (shaders/tile_project.comp): per splat, cull, screen quantities, tile rectangle,
   ``tiles_touched``.
2. ``scan``: exclusive prefix sum of ``tiles_touched`` -- read back, NumPy ``cumsum``, uploaded.
   (The counts are needed on the CPU anyway to size the key buffer.)
3. ``emit_keys`` (shaders/tile_emit.comp): one 64-bit key per (splat, tile).
4. ``sort``: keys read back and sorted by NumPy, written back.  Measured on the 2-core llvmpipe
   machine: ``np.sort`` of 1M uint64 keys 9 ms, a stable ``np.argsort`` 118 ms, a compute-shader
   bitonic sort 0.6 s (DESIGN.md section 6).  So the splat index is packed into the key's low
   bits whenever it fits (:class:`KeyLayout`), which makes a plain sort of the keys equal the
   reference's stable sort; otherwise the reference layout is sorted stably with a value array.
5. ``tile_ranges``: ``[start, end)`` per tile by ``np.searchsorted`` on the sorted keys (one
   binary search per tile, microseconds), uploaded.
6. ``rasterize`` (shaders/tile_rasterize.comp): one 16 x 16 work group per tile, front to back.

With ``RenderSettings.order`` PER_PIXEL (``--order per-pixel``), ``project`` also writes each
splat's peak-depth coefficients (shaders/lib/peak_depth.glsl) and ``rasterize`` re-sorts each
pixel's contributions within a window of ``order_window`` splats (the twin:
:func:`splatgl.reference.per_pixel.window_order`).

2DGS surfel scenes run the same stages with the ``SURFEL`` define: ``project`` builds the centred
``T = P H`` rows and the surfel's screen box (lib/surfel.glsl) and bins it with the reference's
``box_rect``; ``rasterize`` intersects each pixel's ray with the surfel plane (the reference's
surfel branch).  Keys, sort and ranges are unchanged.

The output is (H, W, 4) float32, RGB = ``C + T_final bg``, alpha = ``1 - T_final``, row 0 at the
top; :meth:`TileRenderer.render` adds the accumulated depth ``D = sum z alpha T``.
"""

from __future__ import annotations

import time

import moderngl
import numpy as np

from ..cameras.view import View
from ..errors import SplatglError
from ..gl import limits
from ..gl.buffers import GrowableBuffer
from ..gl.scene_buffers import SceneBuffers
from ..gl.shaders import ProgramCache
from ..gl.transfers import transfers
from ..scene.splats import Scene, SplatKind
from ..scene.settings import Order, RenderSettings, RendererKind, SortKey
from ..splatmath.peak import check_camera
from ..output.layers import BASE, Layer, RenderOutput
from ..output.under import UnderLayer
from .options import TileOptions
from .registry import Registered, check
from .tile_device import DeviceOrder, device_frame
from .tile_layers import layer_output, layer_switches, size_layer_buffers
from .tile_keys import (MAX_GROUPS, RASTER_BAND_TILES, TILE_EMIT_CHUNK,
                        TILE_LIST_CHUNK, KeyLayout, TileStages, TileTimes, check_splat_buffers,
                        read_keys, splat_buffers, splat_groups, tile_grid)


class TileRenderer(Registered):
    """Renders one scene with the per-tile compute path; reuse across views, then :meth:`release`.

    Attributes: ``scene``, ``options`` (:class:`TileOptions`),
    ``last_times`` (:class:`TileTimes` of the last frame, or None) and ``progress`` (a
    :data:`splatgl.progress.ProgressCallback` told the tiles rasterized after each band of the
    last stage, or None).
    """

    kind = RendererKind.TILE

    def __init__(self, ctx: moderngl.Context, scene: Scene, options: TileOptions | RenderSettings,
                 programs: ProgramCache | None = None):
        options = self.own(options)    # the inria rules only, no emulation knobs
        self.per_pixel = options.order is Order.PER_PIXEL
        self.ctx, self.scene = ctx, scene
        self.programs = programs or ProgramCache(ctx)
        self.surfel, self.count = scene.kind is SplatKind.SURFEL_2D, scene.count
        check_splat_buffers(ctx, self.count, self.surfel, self.per_pixel)  # before allocating
        self.scene_buffers = SceneBuffers(ctx, scene, options.gpu_storage) if self.count else None
        self._max_block = limits.storage_block_size(ctx)
        self._bufs = splat_buffers(ctx, self.count, self.surfel, self.per_pixel)
        self.last_times: TileTimes | None = None   # and the progress callback:
        self.progress = None
        self._switches: dict[str, object] = {}   # the frame's layer switches (tile_layers.py)
        #: The device-resident order (``--sort gpu``, :mod:`splatgl.renderers.tile_device`)
        self.device = DeviceOrder.make(ctx, self.programs, self.count, self._max_block, options)

    # ------------------------------------------------------------------------------ programs
    def _defines(self, layout: KeyLayout | None = None) -> dict[str, object]:
        d: dict[str, object] = {"TILE_LIST_CHUNK": TILE_LIST_CHUNK, "TILE_EMIT_CHUNK": TILE_EMIT_CHUNK}
        d.update(self._switches)
        d.update(dict(self.device.chunks(), DEVICE_SORT=1) if self.device else {})
        if layout is not None and layout.packed:
            d["KEY_PACKED"] = 1
        if self.surfel:
            d["SURFEL"] = 1
        if self.per_pixel:              # per-pixel order, a window of order_window splats
            d["PER_PIXEL"] = 1
            d["ORDER_WINDOW"] = self.options.order_window
        return d

    def _project_program(self, view: View) -> moderngl.ComputeShader:
        cap = self.options.sh_degree
        d = self._defines()
        d["SH_DEGREE"] = self.scene.sh_degree if cap is None else min(cap, self.scene.sh_degree)
        d["SH_REST_COEFFS"] = self.scene_buffers.sh_rest_coeffs
        d.update(self.scene_buffers.defines())
        if self.options.antialias:
            d["ANTIALIAS"] = 1
        check(self.kind, scene=self.scene, model=view.model)    # no panoramas
        d.update(view.defines)
        return self.programs.compute("tile_project.comp", d)

    def _set(self, prog: moderngl.ComputeShader, **values) -> None:
        for name, value in values.items():
            if name in prog:
                prog[name].value = value

    def _bind_all(self) -> None:
        if self.scene_buffers is not None:
            self.scene_buffers.bind()
        for b in self._bufs.values():
            b.bind()
        if self.device is not None:
            self.device.bind_sorter()

    # -------------------------------------------------------------------------------- stages
    def _project(self, view: View, grid: tuple[int, int]) -> None:
        prog = self._project_program(view)
        view.set_uniforms(prog)
        self._set(prog, u_count=self.count, u_grid=grid)
        transfers(self.ctx).uniforms(prog)
        prog.run(*splat_groups(self.count))
        self.ctx.memory_barrier()

    def _scan(self) -> tuple[np.ndarray, int]:
        """Exclusive prefix sum of tiles_touched -> (counts (N,) uint32, total keys M)."""
        counts = self._bufs["TOUCHED"].read(self.count * 4, np.uint32)
        ends = np.cumsum(counts, dtype=np.uint64)
        total = int(ends[-1]) if len(ends) else 0
        if total * 8 > self._max_block:
            raise SplatglError(f"the tile renderer needs {total} keys ({total * 8} bytes), more than "
                               f"this OpenGL's storage-block limit of {self._max_block} bytes")
        if total:
            transfers(self.ctx).write(self._bufs["OFFSETS"].buf,
                                      (ends - counts).astype(np.uint32).tobytes())
        return counts, total

    def _emit(self, view: View, layout: KeyLayout, grid: tuple[int, int], total: int,
              counts: np.ndarray) -> None:
        self._bufs["KEYS"].ensure(total * 8)
        if not layout.packed:
            self._bufs["VALUES"].ensure(total * 4)
        self._bind_all()
        d = self._defines(layout)
        d.update(view.defines)              # the per-pixel order's keys: ORTHOGRAPHIC rays
        prog = self.programs.compute("tile_emit.comp", d)
        self._set(prog, u_count=self.count, u_grid=grid, u_tile_shift=layout.tile_shift,
                  u_depth_shift=layout.depth_shift)
        cam = view.camera
        self._set(prog, u_rays=(cam.cx, cam.cy, cam.fx, cam.fy))
        if self.device is not None:     # chunks sized on the device
            return self.device.emit(prog, self._bufs["STATE"].buf, grid[0] * grid[1])
        for first in range(0, int(counts.max(initial=0)), TILE_EMIT_CHUNK):
            self._set(prog, u_first=first)
            transfers(self.ctx).uniforms(prog)
            prog.run(*splat_groups(self.count))
        self.ctx.memory_barrier()

    def _sort(self, layout: KeyLayout, total: int) -> np.ndarray:
        """Sort the emitted keys on the CPU and write them back; returns the sorted keys."""
        keys, values = read_keys(self._bufs, layout, total)
        if layout.packed:
            keys = np.sort(keys)
        else:
            order = np.argsort(keys, kind="stable")
            keys, values = keys[order], values[order]
            transfers(self.ctx).write(self._bufs["VALUES"].buf, values.tobytes())
        transfers(self.ctx).write(self._bufs["KEYS"].buf, keys.tobytes())
        return keys

    def _rasterize(self, view: View, layout: KeyLayout, grid: tuple[int, int],
                   ranges: np.ndarray | None) -> None:
        """``ranges`` None: the device order's (its passes' dispatches sized on the device)."""
        indirect = None if ranges is not None else self.device.raster_offsets(grid[0] * grid[1])
        passes = len(indirect) if indirect else max(1, -(-int(
            (ranges[:, 1] - ranges[:, 0]).max(initial=0)) // TILE_LIST_CHUNK))
        pixels = view.width * view.height
        self._bufs["OUT_RGBA"].ensure(pixels * 16)
        self._bufs["OUT_DEPTH"].ensure(pixels * 4)
        self._bind_all()
        d = self._defines(layout)
        d.update(view.defines)          # surfels: orthographic T_2 = (0, 0, 1)
        prog = self.programs.compute("tile_rasterize.comp", d)
        background = (0.0, 0.0, 0.0) if "UNDER" in self._switches else self.options.background
        self._set(prog, u_grid=grid, u_size=(view.width, view.height),
                  u_background=background, u_index_mask=layout.index_mask)
        cam = view.camera
        self._set(prog, u_rays=(cam.cx, cam.cy, cam.fx, cam.fy))   # the per-pixel order's rays
        band = self.device.band(grid) if self.device else max(1, RASTER_BAND_TILES // grid[0])
        self._set(prog, u_passes=passes)
        for row0 in range(0, grid[1], band):
            self._set(prog, u_tile_row0=row0)
            for p in range(passes):
                self._set(prog, u_pass=p)
                transfers(self.ctx).uniforms(prog)
                (prog.run_indirect(self._bufs["STATE"].buf, indirect[p]) if indirect  # whole bands
                 else prog.run(grid[0], min(band, grid[1] - row0), 1))
                if p + 1 < passes:
                    self.ctx.memory_barrier()     # the next pass reads this one's state
            if band < grid[1]:
                self.ctx.finish()  # Python sees Ctrl-C / SIGTERM here, between bands
                transfers(self.ctx).sync()
                if self.progress is not None:
                    self.progress(min(row0 + band, grid[1]) * grid[0], grid[0] * grid[1],
                                  "tile renderer: rasterizing tiles")
        self.ctx.memory_barrier()

    # ----------------------------------------------------------------------------- frames
    def _frame(self, view: View, stages: bool = False):
        """Run every stage; returns (layout, counts, emitted keys/values or None, sorted keys)."""
        grid = tile_grid(view.width, view.height)
        n_tiles = grid[0] * grid[1]
        if self.per_pixel:
            check_camera(view.camera)
        if grid[0] > MAX_GROUPS or grid[1] > MAX_GROUPS:
            raise SplatglError(f"image of {view.width} x {view.height} has too many tiles")
        layout = KeyLayout.choose(self.count, n_tiles)
        clock = [time.perf_counter()]

        def lap() -> None:
            self.ctx.finish()
            transfers(self.ctx).sync()
            clock.append(time.perf_counter())

        if self.device is not None:
            return device_frame(self, view, grid, lap, clock, stages)
        counts, total, emitted, keys = np.zeros(0, np.uint32), 0, None, np.zeros(0, np.uint64)
        self._bind_all()
        if self.count:
            self._project(view, grid)
        lap()
        if self.count:
            counts, total = self._scan()
        lap()
        if total:
            self._emit(view, layout, grid, total, counts)
            if stages:
                emitted = read_keys(self._bufs, layout, total)
        lap()
        if total:
            keys = self._sort(layout, total)
        lap()
        ranges = _cpu_ranges(self._bufs, layout, keys, n_tiles)
        lap()
        self._rasterize(view, layout, grid, ranges)
        lap()
        self._frame_clock = (clock, total)
        return layout, counts, emitted, keys

    def _times(self, readback: float, moved) -> TileTimes:
        clock, total = self._frame_clock
        d = np.diff(clock)
        return TileTimes(*(float(v) for v in d), float(readback),
                         None if total is None else int(total), moved, self.device is not None)

    def render(self, view: View, layers: frozenset[Layer] = BASE,
               under: UnderLayer | None = None) -> RenderOutput:
        """The ``layers`` of one view (colour and alpha always, the others when asked:
        :mod:`splatgl.renderers.tile_layers`); RGB = C + (1 - A) background, alpha = A (with
        ``under``, composited over the geometry); row 0 is the top."""
        layers = frozenset(layers)
        before = transfers(self.ctx).snapshot()
        self._switches = layer_switches(layers, under, self.per_pixel)
        try:
            size_layer_buffers(self._bufs, self._switches, self.count, view.width * view.height,
                               under)
            h, w = view.height, view.width
            while True:   # the device order: drawn again after an overflow, seen in the image
                self._frame(view)
                t0 = time.perf_counter()
                rgba = self._bufs["OUT_RGBA"].read(h * w * 16, np.float32).reshape(h, w, 4)
                if self.device is None or not self.device.overflowed(rgba):
                    break
        finally:
            switches, self._switches = self._switches, {}
        dep = (self._bufs["OUT_DEPTH"].read(h * w * 4, np.float32).reshape(h, w)
               if Layer.DEPTH in layers else None)
        out = layer_output(self._bufs, rgba, dep, layers, under if switches else None,
                           self.options.background)
        self.last_times = self._times(time.perf_counter() - t0,
                                      transfers(self.ctx).snapshot().since(before))
        return out

    def debug_stages(self, view: View) -> TileStages:
        """Run one frame and return its integer stages in the reference's layout."""
        return _debug_stages(self, view)

    def release(self) -> None:
        if self.device is not None:
            self.device.release()
            self.device = None
        for b in self._bufs.values():
            b.release()
        if self.scene_buffers is not None:
            self.scene_buffers.release()
            self.scene_buffers = None


def _debug_stages(r: TileRenderer, view: View) -> TileStages:
    """:meth:`TileRenderer.debug_stages`."""
    layout, counts, emitted, keys = r._frame(view, stages=True)
    rect = (r._bufs["RECT"].read(r.count * 16, np.uint32).reshape(-1, 4).astype(np.int64)
            if r.count else np.zeros((0, 4), np.int64))
    if emitted is None:
        e_keys, e_vals = np.zeros(0, np.uint64), np.zeros(0, np.int64)
    else:
        e_keys, e_vals = layout.to_reference(*emitted)
    values = None if layout.packed else r._bufs["VALUES"].read(len(keys) * 4, np.uint32)
    if r.device is not None:    # the device order: VALUES holds the emitted ones
        values = r.device.sorted[1]
    s_keys, s_vals = layout.to_reference(keys, values)
    grid = tile_grid(view.width, view.height)
    ranges = r._bufs["RANGES"].read(grid[0] * grid[1] * 8, np.uint32).reshape(-1, 2)
    return TileStages(counts.astype(np.int64), rect[:, :2], rect[:, 2:], e_keys, e_vals,
                      s_keys, s_vals, ranges.astype(np.int64))


def _cpu_ranges(bufs: dict[str, GrowableBuffer], layout: KeyLayout, keys: np.ndarray,
                n_tiles: int) -> np.ndarray:
    """The CPU order's tile ranges: (n_tiles, 2) uint32 [start, end) per tile, uploaded."""
    first = np.arange(n_tiles, dtype=np.uint64) << np.uint64(layout.tile_shift)
    starts = np.empty(n_tiles + 1, np.int64)
    starts[:n_tiles] = np.searchsorted(keys, first, "left")
    starts[n_tiles] = len(keys)
    ranges = np.stack([starts[:-1], starts[1:]], 1).astype(np.uint32)
    bufs["RANGES"].upload(ranges.tobytes())
    return ranges
