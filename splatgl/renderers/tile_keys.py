"""The tile renderer's keys and records: the tile grid, the sort keys' bit layout, its per-view
buffers (each checked against the driver's limit on one buffer), stage times, and the integer
stages compared with the NumPy reference (:mod:`splatgl.renderers.tile`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..constants import TILE_LIST_CHUNK, TILE_SIZE  # noqa: F401 (TILE_LIST_CHUNK: tile.py's)
from ..gl import dispatch
from ..gl.bindings import SPLAT_GROUP, TILE_BINDINGS
from ..gl.buffers import GrowableBuffer
from ..gl.limits import DERIVED_ADVICE, check_splat_buffer
from ..gl.transfers import TransferCounts

#: Largest number of work groups along one dispatch axis guaranteed by OpenGL.
MAX_GROUPS = 65535
#: Bits of a positive float32's pattern (sign bit clear).
DEPTH_BITS = 31
#: Tiles per rasterize dispatch, at most: the image is drawn in bands of whole tile rows, with a
#: finish between bands, so a long frame reports progress and Ctrl-C stops it within one band.
RASTER_BAND_TILES = 512
#: Keys of one splat's tile rectangle one emit dispatch writes at most (the same loop limit: a
#: splat covering a 4096 x 4096 image has 65536 tiles); larger rectangles take more dispatches.
TILE_EMIT_CHUNK = 32768
#: The per-view buffers that grow with the splats, the keys, the tiles or the pixels: name ->
#: (bytes an item, the item), for the driver's limit on one buffer, which each growth checks
#: (:func:`splatgl.gl.limits.check_splat_buffer`, one line naming the buffer).
BUFFER_ITEMS: dict[str, tuple[int, str]] = {
    **{name: (16, "splats") for name in ("MEAN_DEPTH", "CONIC_O", "COLOR", "RECT", "SURFEL",
                                         "NORMAL")},
    "TOUCHED": (4, "splats"), "OFFSETS": (4, "splats"), "SPLAT_ORDER": (4, "splats"),
    "PEAK": (48, "splats"),
    "KEYS": (8, "tile keys"), "VALUES": (4, "tile keys"), "ORDER": (4, "tile keys"),
    "RANGES": (8, "tiles"),
    **{name: (16, "pixels") for name in ("OUT_RGBA", "OUT_NORMAL")},
    "OUT_DEPTH": (4, "pixels"), "UNDER": (4, "pixels"),
    "OUT_ORDERED_F": (8, "pixels"), "OUT_ORDERED_U": (8, "pixels"),
}


def buffer_what(name: str) -> str:
    """How the driver-limit refusal names the tile renderer's buffer ``name``."""
    stride, unit = BUFFER_ITEMS.get(name, (0, ""))
    what = f"the tile renderer's {name.lower().replace('_', ' ')} buffer"
    return f"{what}, {stride} bytes a {unit[:-1]}" if stride else what


def _splat_sizes(surfel: bool, per_pixel: bool) -> dict[str, int]:
    """Bytes a splat of each per-splat buffer a renderer of this kind allocates at once."""
    sizes = {name: BUFFER_ITEMS[name][0] for name in ("MEAN_DEPTH", "CONIC_O", "COLOR", "RECT",
                                                        "TOUCHED", "OFFSETS")}
    if surfel:
        sizes["SURFEL"] = 16
    if per_pixel and not surfel:
        sizes["PEAK"] = 48   # the peak depth's coefficients
    return sizes


def check_splat_buffers(ctx, n: int, surfel: bool, per_pixel: bool) -> None:
    """Refuse in one line, before anything is allocated, ``n`` splats whose largest per-splat
    buffer the driver cannot hold in one (:func:`splatgl.gl.limits.check_splat_buffer`)."""
    sizes = _splat_sizes(surfel, per_pixel)
    largest = max(sizes, key=sizes.get)
    check_splat_buffer(ctx, n, n * sizes[largest], buffer_what(largest), advice=DERIVED_ADVICE)


def splat_buffers(ctx, n: int, surfel: bool, per_pixel: bool) -> dict[str, GrowableBuffer]:
    """The per-view buffers by name (:data:`TILE_BINDINGS`), the per-splat ones sized for ``n``
    (each growth checked against the driver's limit, in :class:`GrowableBuffer`)."""
    bufs = {name: GrowableBuffer(ctx, b, slack=0.25, what=buffer_what(name),
                                 stride=BUFFER_ITEMS.get(name, (0,))[0],
                                 unit=BUFFER_ITEMS.get(name, (0, "splats"))[1])
            for name, b in TILE_BINDINGS.items()}
    for name, stride in _splat_sizes(surfel, per_pixel).items():
        bufs[name].ensure(n * stride)
    return bufs


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
    #: Keys the frame emitted; None where they stayed on the device (``--sort gpu``: a frame
    #: reads back nothing but the image).
    n_keys: int | None
    #: The frame's transfers (:mod:`splatgl.gl.transfers`), apart from the one-time scene upload.
    transfers: TransferCounts = TransferCounts()
    #: Whether the order stayed on the device (``--sort gpu``, :mod:`.tile_device`).
    device_order: bool = False

    @property
    def total(self) -> float:
        return (self.project + self.scan + self.emit + self.sort + self.ranges + self.rasterize
                + self.readback)

    @property
    def ordering(self) -> float:
        return self.sort

    @property
    def drawing(self) -> float:
        return self.rasterize

    def summary(self, count: int) -> str:
        keys = "tile keys on the device" if self.n_keys is None else f"{self.n_keys:,} tile keys"
        return f"splats {count:,}, {keys}"


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


def splat_groups(n: int) -> tuple[int, int]:
    """(groups_x, groups_y) covering ``n`` splats with 256-invocation groups (lib/tile_common),
    neither above :func:`splatgl.gl.dispatch.portable_limit`."""
    return dispatch.grid(max(1, -(-n // SPLAT_GROUP)), dispatch.portable_limit())


def read_keys(bufs: dict, layout: KeyLayout, total: int
              ) -> tuple[np.ndarray, np.ndarray | None]:
    """The ``total`` keys (and values, unpacked) in the key buffers, read back."""
    keys = bufs["KEYS"].read(total * 8, np.uint64)
    values = None if layout.packed else bufs["VALUES"].read(total * 4, np.uint32)
    return keys, values
