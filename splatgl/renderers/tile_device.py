"""The tile renderer's device-resident order (``--sort gpu``, issue 40): the stages between
``project`` and ``rasterize`` run on the GPU, sized from the device, and nothing but the image
comes back.

1. ``scan`` (shaders/tile_scan.comp): the exclusive prefix sum of tiles_touched, reduce then
   scan over blocks of TILE_SCAN_GROUP * TILE_SCAN_ITEMS splats; its last block also writes the
   frame's state: the keys' total, an overflow flag when the total exceeds the key buffers'
   capacity, the count the sort reads and the indirect dispatch sizes of the stages after it.
2. ``emit`` (tile_emit.comp with DEVICE_SORT): the reference layout's keys ``(tile << 32) |
   depth bits`` and splat indices, as the CPU order emits them, plus the radix sorter's keys
   (the depth bits) and values (each key's emission place); its chunks are indirect
   dispatches, skipped after an overflow.
3. ``sort`` (:class:`splatgl.gl.radix_sort.RadixSorter`, each sort over only the bits its keys
   differ in, its count read on the device: ``device_count``).  The global order
   (:attr:`DeviceOrder.presort`): before the scan, the N splats sorted by depth (stable: ties
   by index); the scan and the emission walk them in that order and emit (tile, splat index);
   one stable sort by the tile (few bits) gives the (tile, depth) order, ties by index.  The
   per-pixel order (a per-tile key depth): the emitted keys sorted by depth, then (tile_ranges
   stage 1 gathers each sorted key's tile) by tile: an LSD sort by the low word then the high
   word is the stable sort of the 64-bit keys, ties in emission order.  Both: the CPU order
   exactly.
4. ``ranges`` (tile_ranges.comp): where the tile changes, the sorted splat indices, and the
   rasterize passes the longest tile list needs, as indirect dispatches.

An overflow draws nothing useful: the rasterizer then writes alpha
:data:`~splatgl.constants.TILE_OVERFLOW_ALPHA` (never a drawn alpha) into every pixel, and
:meth:`DeviceOrder.overflowed`, given the image read back, sees it in the first pixel.  Only
then is the 8-byte status (the keys' total) read, the buffers grown to the total and a quarter
more, and the frame drawn again; the capacity is kept for the frames after.  A frame that fits
reads back the image alone: no status word, no extra synchronisation point.

Memory: the key capacity starts at ``TILE_KEYS_PER_SPLAT`` (8) keys a splat and grows only to
1.25x a frame's measured total, never past the key limit (the smaller of
``GL_MAX_SHADER_STORAGE_BLOCK_SIZE`` and :func:`splatgl.gl.limits.buffer_limit`, over 8 bytes a
key; a frame needing more is refused in one line).  A key of capacity holds 8 + 4 + 4 bytes of
keys, values and order (with the buffers' quarter of slack, 20) and the sorter's 16 (24 with
the block passes a software device sorts with, :mod:`splatgl.gl.radix_block`): at most 36
bytes a key on a GPU, 1.6 GiB for 6M splats' first 48M keys; 44 on llvmpipe, 0.7 GiB at its
128 MiB block (16.8M keys).  The NumPy twins are the CPU order of :mod:`splatgl.renderers.tile`
(:func:`scan_twin`, :func:`ranges_twin`).
"""

from __future__ import annotations

import moderngl
import numpy as np

from ..constants import TILE_KEYS_PER_SPLAT, TILE_OVERFLOW_ALPHA, TILE_SCAN_ITEMS
from ..errors import SplatglError
from ..gl import dispatch
from ..gl.bindings import (TILE_BINDING_SORT_KEYS, TILE_BINDING_SORT_VALUES, TILE_SCAN_GROUP)
from ..gl.egl_devices import is_software_renderer
from ..gl.limits import DERIVED_ADVICE, buffer_limit, check_splat_buffer
from ..gl.radix_sort import RadixSorter
from ..gl.shaders import ProgramCache
from ..gl.transfers import transfers
from ..scene.settings import Order, SortKey
from .tile_keys import (RASTER_BAND_TILES, TILE_EMIT_CHUNK, TILE_LIST_CHUNK, KeyLayout,
                        read_keys, splat_groups)

#: Bytes of the state before its dispatch arguments (lib/tile_common.glsl TileState), and the
#: byte offsets of the total (the overflow flag follows it) and of the count the sort reads.
_ARGS = 48
_TOTAL = 0
_SORT_COUNT = 8
_SPLATS = 20
#: Keys the key buffers first hold at the least.
_MIN_CAPACITY = 4096




def scan_twin(counts: np.ndarray) -> tuple[np.ndarray, int]:
    """NumPy twin of tile_scan.comp: (exclusive prefix sum of ``counts`` (N,), total)."""
    ends = np.cumsum(counts, dtype=np.uint64)
    total = int(ends[-1]) if len(ends) else 0
    return (ends - counts).astype(np.uint32), total


def ranges_twin(tiles: np.ndarray, n_tiles: int) -> np.ndarray:
    """NumPy twin of tile_ranges.comp stage 2: (n_tiles, 2) ``[start, end)`` of each tile's
    run in ``tiles`` (M,), the sorted keys' tiles; (0, 0) for a tile without keys."""
    ranges = np.zeros((n_tiles, 2), np.uint32)
    if len(tiles):
        t, start, count = np.unique(tiles, return_index=True, return_counts=True)
        ranges[t, 0] = start
        ranges[t, 1] = start + count
    return ranges


class DeviceOrder:
    """The device order's buffers, programs and capacity for one :class:`TileRenderer`."""

    def __init__(self, ctx: moderngl.Context, programs: ProgramCache, n_splats: int,
                 max_block: int, capacity: int | None = None):
        self.ctx, self.programs, self.count, self.max_block = ctx, programs, n_splats, max_block
        #: Keys the key buffers hold (grown after an overflow, never shrunk).
        self.capacity = capacity or min(max(_MIN_CAPACITY, TILE_KEYS_PER_SPLAT * n_splats),
                                        self.key_limit)
        self.sorter = RadixSorter(ctx, programs)
        #: A software renderer (llvmpipe) ends an invocation's loops after 65535 iterations,
        #: so long tile lists take passes of TILE_LIST_CHUNK entries there, and the image is
        #: drawn in bands with a finish between them (Ctrl-C); a GPU blends every list in one
        #: pass over the whole image (no mostly empty pass dispatches, no finishes).
        self.software = is_software_renderer(ctx.info.get("GL_RENDERER", ""))
        #: The global order's shape: the splats sorted by depth (N keys), emitted in that
        #: order, the keys sorted by tile alone (few bits).  The per-pixel order's keys carry
        #: a per-tile depth, so it sorts the emitted keys by depth, then by tile.
        self.presort = True
        #: Frames drawn again after an overflow (for tests and the timings).
        self.retries = 0
        #: Keys of the last frame where it was read (an overflow, or ``debug_stages``), else
        #: None: a frame that fits reads nothing but the image.
        self.total: int | None = None
        self._state = None   # the renderer's STATE buffer (GrowableBuffer), from ensure()
        #: The sorted keys and splat indices, read back by ``TileRenderer.debug_stages``.
        self.sorted: tuple[np.ndarray, np.ndarray] | None = None

    @classmethod
    def make(cls, ctx, programs, n_splats: int, max_block: int, options) -> "DeviceOrder | None":
        """The device order where the tile renderer's ``options`` ask for it (``--sort gpu``)
        and there are splats, else None (the CPU order; ``--sort bucket16`` the registry
        refuses)."""
        if options.sort_key is SortKey.GPU and n_splats:
            order = cls(ctx, programs, n_splats, max_block)
            order.presort = options.order is Order.GLOBAL
            return order
        return None

    @property
    def key_limit(self) -> int:
        """Keys one key buffer may hold: 8 bytes each within the storage block and the
        driver's limit on one buffer."""
        return min(self.max_block, buffer_limit(self.ctx)[0]) // 8

    def slots(self, n_tiles: int) -> tuple[int, int]:
        """(emit dispatches, rasterize passes) the state holds arguments for: enough for the
        largest rectangle (every tile) and the longest list (every splat, or every key)."""
        emit = max(1, -(-n_tiles // TILE_EMIT_CHUNK))
        raster = max(1, -(-min(self.count, self.capacity) // self.list_chunk))
        return emit, raster

    def ensure(self, bufs: dict, n_tiles: int) -> None:
        """Size the per-view buffers for the capacity and this grid."""
        if self.capacity * 8 > self.max_block:
            raise SplatglError(f"the tile renderer needs {self.capacity} keys "
                               f"({self.capacity * 8} bytes), more than this OpenGL's "
                               f"storage-block limit of {self.max_block} bytes")
        emit, raster = self.slots(n_tiles)
        self._state = bufs["STATE"]
        bufs["STATE"].ensure(_ARGS + 16 * (emit + raster))
        bufs["SCAN_BLOCKS"].ensure(8 * self.blocks)
        bufs["KEYS"].ensure(8 * self.capacity)
        bufs["VALUES"].ensure(4 * self.capacity)
        bufs["ORDER"].ensure(4 * self.capacity)
        bufs["RANGES"].ensure(8 * n_tiles)
        bufs["SPLAT_ORDER"].ensure(4 * self.count)
        self.sorter.reserve(max(self.capacity, self.count))

    @property
    def list_chunk(self) -> int:
        """Entries of a tile's list one rasterize pass blends at most."""
        return TILE_LIST_CHUNK if self.software else 1 << 30

    def band(self, grid: tuple[int, int]) -> int:
        """Tile rows one rasterize dispatch covers."""
        return max(1, RASTER_BAND_TILES // grid[0]) if self.software else grid[1]

    def chunks(self) -> dict[str, int]:
        """The chunk defines of the device order's programs."""
        return dict({"TILE_EMIT_CHUNK": TILE_EMIT_CHUNK, "TILE_LIST_CHUNK": self.list_chunk},
                    **({"DEVICE_PRESORT": 1} if self.presort else {}))

    @property
    def blocks(self) -> int:
        return max(1, -(-self.count // (TILE_SCAN_GROUP * TILE_SCAN_ITEMS)))

    def bind_sorter(self) -> None:
        """The sorter's A buffers at the tile family's points (after the renderer's own)."""
        keys, values = self.sorter.buffers()
        keys.bind_to_storage_buffer(TILE_BINDING_SORT_KEYS)
        values.bind_to_storage_buffer(TILE_BINDING_SORT_VALUES)

    def scan(self, n_tiles: int) -> None:
        prog = self.programs.compute("tile_scan.comp", self.chunks())
        emit, _ = self.slots(n_tiles)
        for name, value in (("u_count", self.count), ("u_blocks", self.blocks),
                            ("u_capacity", self.capacity), ("u_emit_slots", emit),
                            ("u_splat_groups", splat_groups(self.count)),
                            ("u_group_limit", dispatch.portable_limit())):
            if name in prog:
                prog[name].value = value
        for stage, groups in ((0, self.blocks), (1, 1), (2, self.blocks)):
            prog["u_stage"].value = stage
            transfers(self.ctx).uniforms(prog)
            dispatch.run(prog, groups, f"{self.count} splats' tile counts")
            self.ctx.memory_barrier()

    def depth_presort(self, bufs: dict, n_tiles: int, rebind) -> None:
        """The global order's first step: the splats sorted by depth (stably: ties by index),
        their indices copied into SPLAT_ORDER for the scan and the emission."""
        prog = self.programs.compute("tile_ranges.comp", self.chunks())
        prog["u_stage"].value = 4
        prog["u_splats"].value = self.count
        transfers(self.ctx).uniforms(prog)
        rebind()
        prog.run(*splat_groups(self.count))
        self.ctx.memory_barrier()
        self.sorter.sort_buffers(self.count, device_count=(bufs["STATE"].buf, _SPLATS))
        self.ctx.copy_buffer(bufs["SPLAT_ORDER"].buf, self.sorter.buffers()[1], 4 * self.count)
        self.ctx.memory_barrier()
        rebind()

    def emit(self, prog: moderngl.ComputeShader, state: moderngl.Buffer, n_tiles: int) -> None:
        """Run ``prog`` (tile_emit.comp, DEVICE_SORT, uniforms set) once per chunk slot,
        each an indirect dispatch the scan sized (no groups past the largest rectangle)."""
        emit, _ = self.slots(n_tiles)
        for c in range(emit):
            prog["u_first"].value = c * TILE_EMIT_CHUNK
            transfers(self.ctx).uniforms(prog)
            prog.run_indirect(state, _ARGS + 16 * c)
        self.ctx.memory_barrier()

    def sort_and_ranges(self, state: moderngl.Buffer, n_tiles: int, raster_args: tuple,
                        rebind, lap) -> None:
        """The two sorts and the key passes; ``rebind()`` binds the renderer's buffers again
        after each sort (the sorter binds its own at overlapping points); ``lap()`` ends the
        sort's time and starts the ranges'."""
        prog = self.programs.compute("tile_ranges.comp", self.chunks())
        emit, raster = self.slots(n_tiles)
        for name, value in (("u_tiles", n_tiles), ("u_raster_args", raster_args),
                            ("u_emit_slots", emit), ("u_raster_slots", raster)):
            if name in prog:
                prog[name].value = value
        tile_groups = splat_groups(n_tiles)

        def stage(s: int, groups=None) -> None:
            prog["u_stage"].value = s
            transfers(self.ctx).uniforms(prog)
            if groups is None:
                prog.run_indirect(state, _ARGS - 16)   # ts_key_args
            else:
                prog.run(*groups)
            self.ctx.memory_barrier()

        if not self.presort:   # by depth, then gather each sorted key's tile
            self.sorter.sort_buffers(self.capacity, device_count=(state, _SORT_COUNT))
            rebind()
            stage(0, tile_groups)
            stage(1)
        else:
            stage(0, tile_groups)
        self.sorter.sort_buffers(self.capacity, device_count=(state, _SORT_COUNT))
        rebind()
        lap()
        stage(2)
        stage(3, tile_groups)

    def raster_offsets(self, n_tiles: int) -> list[int]:
        """Byte offsets of the rasterize passes' dispatch arguments."""
        emit, raster = self.slots(n_tiles)
        return [_ARGS + 16 * (emit + p) for p in range(raster)]

    def overflowed(self, rgba: np.ndarray) -> bool:
        """Whether the frame whose image (H, W, 4) was read back overflowed the key buffers
        (its first pixel's alpha is :data:`~splatgl.constants.TILE_OVERFLOW_ALPHA`); if so,
        read the status and grow the capacity (the frame is to be drawn again)."""
        if rgba.size == 0 or rgba.reshape(-1, 4)[0, 3] != TILE_OVERFLOW_ALPHA:
            return False
        return self.grow(*self.status())

    def status(self) -> tuple[int, bool]:
        """(the keys' total, overflowed) of the last frame, read back (8 bytes, a sync): after
        an overflow, and for ``debug_stages``."""
        total, over = (int(v) for v in np.frombuffer(self._state.buf.read(8, offset=_TOTAL),
                                                          np.uint32))
        transfers(self.ctx).read(8)
        self.total = total
        return total, bool(over)

    def grow(self, total: int, over: bool) -> bool:
        """After an overflow (``over``) of ``total`` keys, grow the capacity to the total and a
        quarter more (within :attr:`key_limit`; a frame needing more is refused in one line)
        and say so: the frame is to be drawn again."""
        if not over:
            return False
        if total * 8 > self.max_block:   # the CPU order's limit and message
            raise SplatglError(f"the tile renderer needs {total} keys ({total * 8} bytes), more "
                               f"than this OpenGL's storage-block limit of {self.max_block} bytes")
        check_splat_buffer(self.ctx, total, total * 8, "the tile renderer's keys buffer, 8 bytes "
                           "a tile key", "tile keys", DERIVED_ADVICE)
        self.capacity = min(max(self.capacity, total + total // 4), self.key_limit)
        self.retries += 1
        return True

    def release(self) -> None:
        self.sorter.release()


def device_frame(r, view, grid: tuple[int, int], lap, clock, stages: bool):
    """The device order's frame of :class:`TileRenderer` ``r`` (``lap()`` ends a stage
    on ``clock``).  Returns what ``TileRenderer._frame`` does: read back only with ``stages``,
    which reads the status too and draws again, grown, after an overflow; without, the
    renderer sees an overflow in the image it reads (:meth:`DeviceOrder.overflowed`)."""
    dev, n_tiles = r.device, grid[0] * grid[1]
    layout = KeyLayout(32, 0, False)       # the reference's: the sort needs no packing
    state = lambda: r._bufs["STATE"].buf             # noqa: E731
    band = dev.band(grid)
    while True:
        dev.ensure(r._bufs, n_tiles)
        r._bind_all()
        r._project(view, grid)
        lap()
        if dev.presort:
            dev.depth_presort(r._bufs, n_tiles, r._bind_all)
        dev.scan(n_tiles)
        lap()
        r._emit(view, layout, grid, 0, None)
        lap()
        dev.sort_and_ranges(state(), n_tiles, (grid[0], band, 1), r._bind_all, lap)
        lap()
        r._rasterize(view, layout, grid, None)
        lap()
        if not stages:
            dev.total = None
            r._frame_clock = (clock, None)
            return layout, None, None, None
        if not dev.grow(*dev.status()):
            break
        del clock[1:]
    total = dev.total
    r._frame_clock = (clock, total)
    counts = r._bufs["TOUCHED"].read(r.count * 4, np.uint32)
    keys, values = (np.frombuffer(b.read(4 * total), np.uint32) for b in dev.sorter.buffers())
    if dev.presort:   # (tiles, splat indices): the keys from the splats' depths
        depth = r._bufs["MEAN_DEPTH"].read(r.count * 16, np.float32).reshape(-1, 4)[:, 2]
        dev.sorted = ((keys.astype(np.uint64) << np.uint64(32))
                      | depth.view(np.uint32)[values].astype(np.uint64), values)
        return layout, counts, None, dev.sorted[0]
    emitted = read_keys(r._bufs, layout, total)
    dev.sorted = (emitted[0][values], emitted[1][values])
    return layout, counts, emitted, dev.sorted[0]
