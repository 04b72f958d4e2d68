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

2DGS surfel scenes run the same stages with the ``SURFEL`` define: ``project`` builds the centred
``T = P H`` rows and the surfel's screen box (lib/surfel.glsl) and bins it with the reference's
``box_rect``; ``rasterize`` intersects each pixel's ray with the surfel plane (the reference's
surfel branch).  Keys, sort and ranges are unchanged.

The output is (H, W, 4) float32, RGB = ``C + T_final bg``, alpha = ``1 - T_final``, row 0 at the
top; :meth:`TileRenderer.render_layers` adds the accumulated depth ``D = sum z alpha T``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import moderngl
import numpy as np

from ..cameras.camera import Camera
from ..constants import TILE_SIZE
from ..errors import SplatglError
from ..gl.scene_buffers import BINDING_SH, SceneBuffers
from ..gl.shaders import ProgramCache
from .quad import set_camera_uniforms
from ..output.layers import RenderOutput
from ..model.scene import Scene, SplatKind
from ..model.settings import RenderSettings, resolve_near

#: Storage-buffer bindings of shaders/lib/tile_common.glsl and tile_rasterize.comp (after the
#: scene's 0..BINDING_SH); handed to GLSL as TILE_BINDING_* defines.
BINDINGS = {name: BINDING_SH + 1 + i for i, name in enumerate(
    ("MEAN_DEPTH", "CONIC_O", "COLOR", "RECT", "TOUCHED", "OFFSETS", "KEYS", "VALUES", "RANGES",
     "OUT_RGBA", "OUT_DEPTH", "SURFEL"))}
#: Invocations per work group of the per-splat stages (project, emit).
SPLAT_GROUP = 256
#: Largest number of work groups along one dispatch axis guaranteed by OpenGL.
MAX_GROUPS = 65535
#: Bits of a positive float32's pattern (sign bit clear).
DEPTH_BITS = 31
#: Tiles per rasterize dispatch, at most: the image is drawn in bands of whole tile rows, with a
#: finish between bands, so a long frame reports progress and Ctrl-C stops it within one band.
RASTER_BAND_TILES = 512
#: Entries of a tile's sorted list one rasterize pass blends at most; longer lists take more
#: passes (the pixel state carried in the output buffers).  llvmpipe ends all loops of an
#: invocation after 65535 iterations in total (gallivm's LP_MAX_TGSI_LOOP_ITERATIONS), which a
#: single pass over a 55k-splat tile exceeded, leaving the tile blank; a pass of 16384 entries
#: runs about 2 x 16384 + 64 iterations (the blend loop, and the serial scan of invocation 0).
TILE_LIST_CHUNK = 16384
#: Keys of one splat's tile rectangle one emit dispatch writes at most (the same loop limit: a
#: splat covering a 4096 x 4096 image has 65536 tiles); larger rectangles take more dispatches.
TILE_EMIT_CHUNK = 32768


def tile_grid(width: int, height: int) -> tuple[int, int]:
    """(tiles_x, tiles_y) of 16 x 16 tiles covering a ``width`` x ``height`` image."""
    return -(-width // TILE_SIZE), -(-height // TILE_SIZE)


@dataclass(frozen=True)
class KeyLayout:
    """Bit layout of the uint64 sort keys: ``tile << tile_shift | depth_bits << depth_shift``.

    Packed (``packed``): the splat index fills the low ``depth_shift`` bits, so sorting the keys
    alone reproduces the reference's stable sort of ``(tile << 32) | depth_bits``.  Unpacked:
    exactly the reference layout (``tile_shift`` 32, ``depth_shift`` 0) plus a value array.
    """

    tile_shift: int
    depth_shift: int
    packed: bool

    @classmethod
    def choose(cls, n_splats: int, n_tiles: int) -> "KeyLayout":
        index_bits = max(1, (max(n_splats, 1) - 1).bit_length())
        tile_bits = max(1, (max(n_tiles, 1) - 1).bit_length())
        if index_bits + DEPTH_BITS + tile_bits <= 64:
            return cls(index_bits + DEPTH_BITS, index_bits, True)
        return cls(32, 0, False)

    @property
    def index_mask(self) -> int:
        """Mask of the packed index bits (0 when unpacked)."""
        return (1 << self.depth_shift) - 1 if self.packed else 0

    def to_reference(self, keys: np.ndarray, values: np.ndarray | None = None
                     ) -> tuple[np.ndarray, np.ndarray]:
        """(M,) uint64 keys in this layout -> (reference keys (M,) uint64, indices (M,) int64)."""
        if not self.packed:
            return keys.copy(), values.astype(np.int64)
        tile = keys >> np.uint64(self.tile_shift)
        depth = (keys >> np.uint64(self.depth_shift)) & np.uint64((1 << DEPTH_BITS) - 1)
        index = (keys & np.uint64(self.index_mask)).astype(np.int64)
        return (tile << np.uint64(32)) | depth, index


@dataclass(frozen=True)
class TileTimes:
    """Wall-clock seconds of each stage of one tile-renderer frame (GPU stages include a finish)."""

    project: float
    scan: float
    emit: float
    sort: float
    ranges: float
    rasterize: float
    readback: float
    n_keys: int

    @property
    def total(self) -> float:
        return (self.project + self.scan + self.emit + self.sort + self.ranges + self.rasterize
                + self.readback)


@dataclass(frozen=True)
class TileStages:
    """The integer stages of one view, for comparison with :mod:`splatgl.reference`.

    tiles_touched: (N,) int64.  rect_min, rect_max: (N, 2) int64 tile rectangles (x, y).
    emitted_keys, emitted_values: (M,) uint64 reference-layout keys ``(tile << 32) | depth
    bits`` and (M,) int64 splat indices in emission order.  keys, values: the same sorted.
    ranges: (tiles, 2) int64 ``[start, end)``.
    """

    tiles_touched: np.ndarray
    rect_min: np.ndarray
    rect_max: np.ndarray
    emitted_keys: np.ndarray
    emitted_values: np.ndarray
    keys: np.ndarray
    values: np.ndarray
    ranges: np.ndarray


#: The tile renderer returns the shared layer type.
TileImage = RenderOutput


class _Buffer:
    """A storage buffer that grows (never shrinks) to the size asked for; bytes, min 16."""

    def __init__(self, ctx: moderngl.Context, binding: int):
        self.ctx, self.binding, self.buf = ctx, binding, None

    def ensure(self, nbytes: int) -> moderngl.Buffer:
        nbytes = max(int(nbytes), 16)
        if self.buf is None or self.buf.size < nbytes:
            if self.buf is not None:
                self.buf.release()
            self.buf = self.ctx.buffer(reserve=nbytes + nbytes // 4)
        return self.buf

    def bind(self) -> None:
        self.ensure(16).bind_to_storage_buffer(self.binding)

    def read(self, nbytes: int, dtype) -> np.ndarray:
        return np.frombuffer(self.buf.read(size=nbytes), dtype) if nbytes else np.zeros(0, dtype)

    def release(self) -> None:
        if self.buf is not None:
            self.buf.release()
        self.buf = None


def _splat_groups(n: int) -> tuple[int, int]:
    """(groups_x, groups_y) covering ``n`` splats with 256-invocation groups (lib/tile_common)."""
    groups = max(1, -(-n // SPLAT_GROUP))
    gy = -(-groups // MAX_GROUPS)
    return -(-groups // gy), gy


class TileRenderer:
    """Renders one scene with the per-tile compute path; reuse across views, then :meth:`release`.

    Attributes: ``scene``, ``settings``, ``near`` (resolved near plane, world units),
    ``last_times`` (:class:`TileTimes` of the last frame, or None) and ``progress`` (a
    :data:`splatgl.progress.ProgressCallback` told the tiles rasterized after each band of the
    last stage, or None).
    """

    def __init__(self, ctx: moderngl.Context, scene: Scene, settings: RenderSettings,
                 programs: ProgramCache | None = None):
        self.ctx = ctx
        self.scene = scene
        self.settings = settings
        self.programs = programs or ProgramCache(ctx)
        self.near = resolve_near(settings, scene.robust_radius)
        self.surfel = scene.kind is SplatKind.SURFEL_2D
        self.count = scene.count
        self.scene_buffers = SceneBuffers(ctx, scene, settings.gpu_storage) if self.count else None
        self._max_block = int(ctx.info.get("GL_MAX_SHADER_STORAGE_BLOCK_SIZE") or 2 ** 27)
        self._bufs = {name: _Buffer(ctx, b) for name, b in BINDINGS.items()}
        n = self.count
        for name, stride in (("MEAN_DEPTH", 16), ("CONIC_O", 16), ("COLOR", 16), ("RECT", 16),
                             ("TOUCHED", 4), ("OFFSETS", 4)):
            self._bufs[name].ensure(n * stride)
        if self.surfel:
            self._bufs["SURFEL"].ensure(n * 16)
        self.last_times: TileTimes | None = None
        self.progress = None

    # ------------------------------------------------------------------------------ programs
    def _defines(self, layout: KeyLayout | None = None) -> dict[str, object]:
        d: dict[str, object] = {f"TILE_BINDING_{k}": v for k, v in BINDINGS.items()}
        d["SPLAT_GROUP"] = SPLAT_GROUP
        d["TILE_LIST_CHUNK"] = TILE_LIST_CHUNK
        d["TILE_EMIT_CHUNK"] = TILE_EMIT_CHUNK
        if layout is not None and layout.packed:
            d["KEY_PACKED"] = 1
        if self.surfel:
            d["SURFEL"] = 1
        return d

    def _project_program(self, camera: Camera) -> moderngl.ComputeShader:
        cap = self.settings.sh_degree
        d = self._defines()
        d["SH_DEGREE"] = self.scene.sh_degree if cap is None else min(cap, self.scene.sh_degree)
        d["SH_REST_COEFFS"] = self.scene_buffers.sh_rest_coeffs
        d.update(self.scene_buffers.defines())
        if self.settings.antialias:
            d["ANTIALIAS"] = 1
        camera.model.check_support(self.surfel, "tile")
        d.update(camera.model.defines())
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

    # -------------------------------------------------------------------------------- stages
    def _project(self, camera: Camera, grid: tuple[int, int]) -> None:
        prog = self._project_program(camera)
        set_camera_uniforms(prog, camera, self.near, self.scene.anchor)
        self._set(prog, u_count=self.count, u_grid=grid)
        prog.run(*_splat_groups(self.count))
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
            self._bufs["OFFSETS"].buf.write((ends - counts).astype(np.uint32).tobytes())
        return counts, total

    def _emit(self, layout: KeyLayout, grid: tuple[int, int], total: int,
              counts: np.ndarray) -> None:
        self._bufs["KEYS"].ensure(total * 8)
        if not layout.packed:
            self._bufs["VALUES"].ensure(total * 4)
        self._bind_all()
        prog = self.programs.compute("tile_emit.comp", self._defines(layout))
        self._set(prog, u_count=self.count, u_grid=grid, u_tile_shift=layout.tile_shift,
                  u_depth_shift=layout.depth_shift)
        for first in range(0, int(counts.max(initial=0)), TILE_EMIT_CHUNK):
            self._set(prog, u_first=first)
            prog.run(*_splat_groups(self.count))
        self.ctx.memory_barrier()

    def _read_keys(self, layout: KeyLayout, total: int) -> tuple[np.ndarray, np.ndarray | None]:
        keys = self._bufs["KEYS"].read(total * 8, np.uint64)
        values = None if layout.packed else self._bufs["VALUES"].read(total * 4, np.uint32)
        return keys, values

    def _sort(self, layout: KeyLayout, total: int) -> np.ndarray:
        """Sort the emitted keys on the CPU and write them back; returns the sorted keys."""
        keys, values = self._read_keys(layout, total)
        if layout.packed:
            keys = np.sort(keys)
        else:
            order = np.argsort(keys, kind="stable")
            keys, values = keys[order], values[order]
            self._bufs["VALUES"].buf.write(values.tobytes())
        self._bufs["KEYS"].buf.write(keys.tobytes())
        return keys

    def _ranges(self, layout: KeyLayout, keys: np.ndarray, n_tiles: int) -> np.ndarray:
        """(n_tiles, 2) uint32 [start, end) per tile, uploaded."""
        first = np.arange(n_tiles, dtype=np.uint64) << np.uint64(layout.tile_shift)
        starts = np.empty(n_tiles + 1, np.int64)
        starts[:n_tiles] = np.searchsorted(keys, first, "left")
        starts[n_tiles] = len(keys)
        ranges = np.stack([starts[:-1], starts[1:]], 1).astype(np.uint32)
        self._bufs["RANGES"].ensure(n_tiles * 8).write(ranges.tobytes())
        return ranges

    def _rasterize(self, camera: Camera, layout: KeyLayout, grid: tuple[int, int],
                   ranges: np.ndarray) -> None:
        longest = int((ranges[:, 1] - ranges[:, 0]).max(initial=0))
        passes = max(1, -(-longest // TILE_LIST_CHUNK))
        pixels = camera.width * camera.height
        self._bufs["OUT_RGBA"].ensure(pixels * 16)
        self._bufs["OUT_DEPTH"].ensure(pixels * 4)
        self._bind_all()
        d = self._defines(layout)
        d.update(camera.model.defines())          # surfels: orthographic T_2 = (0, 0, 1)
        prog = self.programs.compute("tile_rasterize.comp", d)
        self._set(prog, u_grid=grid, u_size=(camera.width, camera.height),
                  u_background=self.settings.background, u_index_mask=layout.index_mask)
        band = max(1, RASTER_BAND_TILES // grid[0])  # tile rows per dispatch
        self._set(prog, u_passes=passes)
        for row0 in range(0, grid[1], band):
            self._set(prog, u_tile_row0=row0)
            for p in range(passes):
                self._set(prog, u_pass=p)
                prog.run(grid[0], min(band, grid[1] - row0), 1)
                if p + 1 < passes:
                    self.ctx.memory_barrier()     # the next pass reads this one's state
            if band < grid[1]:
                self.ctx.finish()  # Python sees Ctrl-C / SIGTERM here, between bands
                if self.progress is not None:
                    self.progress(min(row0 + band, grid[1]) * grid[0], grid[0] * grid[1],
                                  "tile renderer: rasterizing tiles")
        self.ctx.memory_barrier()

    # ----------------------------------------------------------------------------- frames
    def _frame(self, camera: Camera, stages: bool = False):
        """Run every stage; returns (layout, counts, emitted keys/values or None, sorted keys)."""
        grid = tile_grid(camera.width, camera.height)
        n_tiles = grid[0] * grid[1]
        if grid[0] > MAX_GROUPS or grid[1] > MAX_GROUPS:
            raise SplatglError(f"image of {camera.width} x {camera.height} has too many tiles")
        layout = KeyLayout.choose(self.count, n_tiles)
        clock = [time.perf_counter()]

        def lap() -> None:
            self.ctx.finish()
            clock.append(time.perf_counter())

        counts, total, emitted, keys = np.zeros(0, np.uint32), 0, None, np.zeros(0, np.uint64)
        self._bind_all()
        if self.count:
            self._project(camera, grid)
        lap()
        if self.count:
            counts, total = self._scan()
        lap()
        if total:
            self._emit(layout, grid, total, counts)
            if stages:
                emitted = self._read_keys(layout, total)
        lap()
        if total:
            keys = self._sort(layout, total)
        lap()
        ranges = self._ranges(layout, keys, n_tiles)
        lap()
        self._rasterize(camera, layout, grid, ranges)
        lap()
        self._frame_clock = (clock, total)
        return layout, counts, emitted, keys

    def _times(self, readback: float) -> TileTimes:
        clock, total = self._frame_clock
        d = np.diff(clock)
        return TileTimes(*(float(v) for v in d), float(readback), int(total))

    def render_layers(self, camera: Camera, depth: bool = True) -> TileImage:
        """Colour and (when ``depth``) accumulated depth of one view; see :class:`TileImage`."""
        self._frame(camera)
        t0 = time.perf_counter()
        h, w = camera.height, camera.width
        rgba = self._bufs["OUT_RGBA"].read(h * w * 16, np.float32).reshape(h, w, 4)
        dep = (self._bufs["OUT_DEPTH"].read(h * w * 4, np.float32).reshape(h, w) if depth
               else np.zeros((0, 0), np.float32))
        self.last_times = self._times(time.perf_counter() - t0)
        return TileImage(rgba.copy(), dep.copy())

    def render(self, camera: Camera) -> np.ndarray:
        """(H, W, 4) float32: RGB = C + (1 - A) background, alpha = A; row 0 is the top."""
        return self.render_layers(camera, depth=False).rgba

    def debug_stages(self, camera: Camera) -> TileStages:
        """Run one frame and return its integer stages in the reference's layout."""
        layout, counts, emitted, keys = self._frame(camera, stages=True)
        rect = (self._bufs["RECT"].read(self.count * 16, np.uint32).reshape(-1, 4).astype(np.int64)
                if self.count else np.zeros((0, 4), np.int64))
        if emitted is None:
            e_keys, e_vals = np.zeros(0, np.uint64), np.zeros(0, np.int64)
        else:
            e_keys, e_vals = layout.to_reference(*emitted)
        values = None if layout.packed else self._bufs["VALUES"].read(len(keys) * 4, np.uint32)
        s_keys, s_vals = layout.to_reference(keys, values)
        grid = tile_grid(camera.width, camera.height)
        ranges = self._bufs["RANGES"].read(grid[0] * grid[1] * 8, np.uint32).reshape(-1, 2)
        return TileStages(counts.astype(np.int64), rect[:, :2], rect[:, 2:], e_keys, e_vals,
                          s_keys, s_vals, ranges.astype(np.int64))

    def release(self) -> None:
        for b in self._bufs.values():
            b.release()
        if self.scene_buffers is not None:
            self.scene_buffers.release()
            self.scene_buffers = None
