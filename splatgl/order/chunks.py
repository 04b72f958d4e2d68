"""Chunked cull: whole groups of nearby splats accepted or rejected per view, keys built directly.

At the first culled view the splats that can ever be drawn (opacity >= 1/255) are put in Morton
order of their centres and cut into chunks of :data:`CHUNK` consecutive splats, each with a
bounding sphere of its centres (radius ``r_centre``) and its largest splat reach (``r_max``,
the cull's opacity-aware radius).  Per view, in float64 over the chunks only:

- a chunk whose centre sphere lies beyond the near plane and strictly inside the four side
  planes of the image (both with a float32 rounding margin) keeps every splat: no per-splat
  test runs, only the depth ``z = r . p + t`` (the same float32 operations, in the same order,
  as :func:`splatgl.order.cull.cull_visible`, so the same bits) written straight into the keys;
- a chunk wholly behind the near plane, or wholly outside one side plane widened by its
  largest reach, is dropped without touching its splats;
- the rest (boundary chunks, chunks holding faint splats, every chunk with antialiasing, whose
  peak-alpha bound applies to every splat, and orthographic cameras) take the per-splat cull
  :func:`splatgl.order.cull.cull_visible` on their rows.

The chunk and group spheres and these tests are :mod:`splatgl.order.spheres`.  So the kept set
is exactly :func:`~splatgl.order.cull.cull_visible`'s.  Where numba is installed
(:mod:`splatgl.order.kernels`) a pinhole view runs as one compiled pass instead: the same chunk
tests, the same float32 row tests, the float64 peak bound (rows it cannot call for certain go
back to NumPy's), on two threads from :data:`SPLIT_ROWS` splats; :func:`rows_keys` culls an
arbitrary set of rows (a LOD cut's) the same way.  The output is the sort's
uint64 keys ``(float_bits(z) << 32) | index`` in chunk order; the exact sort orders them by
value (ties by index, as :func:`splatgl.order.sort.depth_sort` does), so the order of the keys
before the sort does not matter.
"""

from __future__ import annotations

import numpy as np

from . import kernels as cull_kernel
from ..cameras.camera import Camera
from ..constants import JACOBIAN_CLAMP
from .cull import CULL_BLOCK, CullData, cull_visible, peak_keeps, plane_constants, view_axis
from ..cameras.view import frustum_of, near_threshold
from ..cameras.equirect import WRAP_FLAG
from ..scene.spatial import morton_order_clamped_box
from .sort import depth_keys
from .spheres import Spheres, sphere_constants

cull_kernel.register(f"{__package__}._numba_cull")  # view_pass, rows_pass, lens_pass (numba)

#: Splats per chunk (the fine level): boundary chunks hold few splats (the per-splat cull
#: runs on those only); the chunk statistics cost 41 bytes per chunk, 0.64 B/splat.
CHUNK = 64
#: Chunks per group (the coarse level, 1024 splats): groups are classified first, and only the
#: chunks of boundary groups one by one, so the per-view work outside the splats stays at a few
#: float64 operations on N / 1024 groups plus the boundary groups' chunks.
GROUP = 16
#: Above this share of the rows in boundary chunks, the per-splat cull runs on all rows in one
#: pass instead (gathering the boundary rows and the accepted runs' calls then cost more than
#: they save; measured on the 0.1M scale scene from close by: 44% boundary, 1.3x slower).
WHOLE_SHARE = 0.35
#: Room for the rows whose peak bound the compiled pass leaves to NumPy (within
#: ``_numba_cull.PEAK_UNSURE``, 1%, of 1/255: about 130 in 100k splats on the scale scene at
#: 1280x720; more than this and the view takes the NumPy path).
UNSURE_ROWS = 1 << 16
#: From this many drawable splats on, the compiled pass runs on two threads (half the groups
#: each); below, starting the second costs about what it saves.
SPLIT_ROWS = 1 << 17


class ChunkedCull:
    """The chunked cull data of one scene (built once, reused for every view).

    Attributes:
        data: :class:`~splatgl.order.cull.CullData` of the drawable splats in chunk order.
        index: (M,) uint32 scene index of each of those rows.
        starts: (C + 1,) int64 row where each chunk starts (and M).
        chunks: :class:`Spheres` of the C chunks.  groups: :class:`Spheres` of the groups of
            :data:`GROUP` consecutive chunks (group g holds chunks ``g * GROUP ...``).
        count: N, the scene's splat count.
    """

    def __init__(self, data: CullData, chunk: int = CHUNK, group: int = GROUP):
        self.count = data.count
        self.group = group
        rows = np.flatnonzero(data.alive)
        rows = rows[morton_order_clamped_box(data.xyz[:, rows].T)]
        faint = data.faint[rows]
        bright, dim = rows[~faint], rows[faint]  # faint splats chunked apart, after the others
        self.index = np.concatenate([bright, dim]).astype(np.uint32)
        self.data = data.subset(self.index)
        self.starts = np.unique(np.concatenate([np.arange(0, bright.size, chunk),
                                                bright.size + np.arange(0, dim.size, chunk),
                                                [self.index.size]])).astype(np.int64)
        firsts = self.starts[:-1]
        if not firsts.size:
            empty = np.zeros(0)
            self.chunks = self.groups = Spheres(np.zeros((0, 3)), empty, empty, empty.astype(bool))
        else:
            xyz = self.data.xyz
            lo = np.stack([np.minimum.reduceat(a, firsts) for a in xyz], 1).astype(np.float64)
            hi = np.stack([np.maximum.reduceat(a, firsts) for a in xyz], 1).astype(np.float64)
            centre = 0.5 * (lo + hi)
            d2 = sum((a.astype(np.float64) - np.repeat(centre[:, k], np.diff(self.starts))) ** 2
                     for k, a in enumerate(xyz))
            self.chunks = Spheres(centre, np.sqrt(np.maximum.reduceat(d2, firsts)),
                                  np.maximum.reduceat(self.data.radius, firsts).astype(np.float64),
                                  firsts < bright.size)
            g = np.arange(0, firsts.size, group)
            g_lo, g_hi = np.minimum.reduceat(lo, g), np.maximum.reduceat(hi, g)
            g_centre = 0.5 * (g_lo + g_hi)
            # a group's sphere holds its chunks' spheres
            spread = np.linalg.norm(centre - np.repeat(g_centre, np.diff(np.append(g, firsts.size)),
                                                       axis=0), axis=1) + self.chunks.r_centre
            self.groups = Spheres(g_centre, np.maximum.reduceat(spread, g),
                                  np.maximum.reduceat(self.chunks.r_max, g),
                                  np.logical_and.reduceat(self.chunks.plain, g))
        self._keys = np.empty(self.index.size, np.uint64)
        self._z, self._tmp = np.empty(CULL_BLOCK, np.float32), np.empty(CULL_BLOCK, np.float32)
        self.views = 0
        #: Rows the compiled pass could not decide for certain (and their camera-space points),
        #: one pair of buffers per half of the groups.
        self._unsure = [(np.empty(UNSURE_ROWS, np.int64), np.empty((UNSURE_ROWS, 3), np.float32))
                        for _ in range(2)]
        #: First group of the second half (the compiled pass's two threads), or 0: one thread.
        self._split = 0
        if self.index.size >= SPLIT_ROWS:
            group_rows = self.starts[np.arange(0, self.starts.size - 1, group)]
            self._split = int(np.searchsorted(group_rows, self.index.size // 2))
        #: Use the compiled kernel: None as :func:`splatgl.order.kernels.policy` says (by default
        #: once it is loaded), False never, True waiting for it to load.
        self.compiled: bool | None = None
        #: Which path the last view took: "compiled" or "numpy".
        self.last_path = "numpy"

    @classmethod
    def from_scene(cls, scene) -> "ChunkedCull":
        """Built from a :class:`splatgl.scene.splats.Scene` through :meth:`CullData.from_scene`."""
        return cls(CullData.from_scene(scene))

    def visible_keys(self, camera: Camera, near: float, antialias: bool = False,
                     scale: float = 1.0) -> np.ndarray:
        """(K,) uint64 sort keys ``(float_bits(z) << 32) | scene index`` of the splats
        :func:`~splatgl.order.cull.cull_visible` keeps, in chunk order (unsorted).

        ``camera`` (a FRUSTUM or BOX model's: :data:`splatgl.order.stage.CULLS`) anchored to
        ``data.xyz``'s origin; ``scale`` multiplies the world radii.  The array is a view of a buffer the next call overwrites: sort (copy) it first.
        """
        n_chunks = self.starts.size - 1
        self.views += 1
        self.last_path = "numpy"
        if camera.is_orthographic or antialias or not n_chunks:
            # orthographic: cull_visible's own path; antialiasing: the peak bound with the
            # compensation factor runs on every splat
            idx, z = cull_visible(self.data, camera, near, antialias, scale)
            return depth_keys(z, self.index[idx], self._keys[:idx.size])
        kern = self._kernel()
        if kern is not None:
            keys = self._compiled_keys(kern, camera, near, scale)
            if keys is not None:
                self.last_path = "compiled"
                return keys
        accept_g, reject_g = self.groups.classify(camera, near, scale)
        accept = np.repeat(accept_g, self.group)[:n_chunks]
        test_g = np.flatnonzero(~(accept_g | reject_g))
        # the boundary groups' chunks, one by one
        ids = (test_g[:, None] * self.group + np.arange(self.group)).ravel()
        ids = ids[ids < n_chunks]
        accept_c, reject_c = self.chunks.take(ids).classify(camera, near, scale)
        accept[ids[accept_c]] = True
        test = np.zeros(n_chunks, bool)
        test[ids[~(accept_c | reject_c)]] = True
        sizes = np.diff(self.starts)
        if sizes[test].sum() > WHOLE_SHARE * self.index.size:  # mostly boundary: one pass
            idx, z = cull_visible(self.data, camera, near, antialias, scale)
            return depth_keys(z, self.index[idx], self._keys[:idx.size])
        out = 0
        r = camera.rotation[2].astype(np.float32)
        t = camera.translation.astype(np.float32)[2]
        for a, b in _runs(accept, self.starts):
            out = self._depth_keys(r, t, a, b, out)
        if test.any():
            rows = _rows(np.flatnonzero(test), self.starts)
            idx, z = cull_visible(self.data.subset(rows), camera, near, antialias, scale)
            depth_keys(z, self.index[rows[idx]], self._keys[out:out + idx.size])
            out += idx.size
        return self._keys[:out]

    def _kernel(self):
        """The compiled kernels if this view should use them, else None (see :attr:`compiled`)."""
        return cull_kernel.for_view(self.views, self.compiled)

    def _compiled_keys(self, kern, camera: Camera, near: float, scale: float
                       ) -> np.ndarray | None:
        """:meth:`visible_keys` through the compiled pass (:func:`splatgl.order._numba_cull.view_pass`),
        with NumPy's peak bound on the few rows it leaves undecided; None in the unlikely case
        that those overflow their buffer (the NumPy path then serves the view).

        From :data:`SPLIT_ROWS` rows on, the groups are split in two halves by rows, the second
        run on :func:`splatgl.order.kernels.helper`'s thread at the same time, and its keys then
        moved down behind the first half's."""
        xyz, data = self.data.xyz, self.data
        peak = peak_constants(camera, scale)
        view, sides = sphere_constants(camera, near, scale)
        args = (self.groups.packed, self.chunks.packed, self.group, xyz[0], xyz[1], xyz[2],
                data.radius, data.faint, data.max_scale, data.opacities, self.index, self.starts,
                camera.rotation.astype(np.float64), camera.translation.astype(np.float64), view,
                sides, camera.rotation.astype(np.float32), camera.translation.astype(np.float32),
                plane_constants(frustum_of(camera), scale), near_threshold(near, np.float32), peak,
                self._keys.view(np.uint32), self._keys.view(np.float32))
        n_groups = self.groups.packed.shape[0]
        split = self._split
        pool = cull_kernel.helper() if split else None
        unsure = self._unsure
        if pool is None:
            n, c = kern.view_pass(0, n_groups, 0, *args, *unsure[0])
            parts = [(0, n, c, unsure[0])]
        else:
            out1 = int(self.starts[split * self.group])
            second = pool.submit(kern.view_pass, split, n_groups, out1, *args, *unsure[1])
            try:
                n0, c0 = kern.view_pass(0, split, 0, *args, *unsure[0])
            finally:
                n1, c1 = second.result()  # its writes must end before the buffer is reused
            parts = [(0, n0, c0, unsure[0]), (out1, n1, c1, unsure[1])]
        if any(c > UNSURE_ROWS for *_, c, _ in parts):
            return None
        n = parts[0][1]
        if len(parts) == 2:
            out1, n1 = parts[1][:2]
            self._keys[n:n + n1] = self._keys[out1:out1 + n1]  # overlapping: NumPy buffers it
            n += n1
        for *_, c, (rows, p) in parts:
            n = settle_unsure(self._keys, n, rows[:c], self.index[rows[:c]], p[:c], data,
                              camera, scale)
        return self._keys[:n]

    def key_buffer(self) -> np.ndarray:
        """(M,) uint64 buffer the culls write keys into (one per drawable splat, reused)."""
        return self._keys

    def _depth_keys(self, r: np.ndarray, t: np.float32, a: int, b: int, out: int) -> int:
        """Keys of every splat of rows ``a:b`` into the buffer from ``out``; returns the new
        end.  Depths ``r . p + t`` by cull_visible's own operations
        (:func:`~splatgl.order.cull.view_axis`): the same bits."""
        z, tmp = self._z, self._tmp
        for start in range(a, b, CULL_BLOCK):  # in-cache blocks
            stop = min(b, start + CULL_BLOCK)
            m = stop - start
            view_axis(self.data.xyz, start, stop, r, t, z[:m], tmp[:m])
            depth_keys(z[:m], self.index[start:stop], self._keys[out:out + m])
            out += m
        return out


def _runs(flags: np.ndarray, starts: np.ndarray) -> list[tuple[int, int]]:
    """Row ranges ``[(a, b), ...]`` of the maximal runs of consecutive chunks with ``flags``."""
    f = np.concatenate([[False], flags, [False]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(f))
    return [(int(starts[i]), int(starts[j])) for i, j in zip(edges[::2], edges[1::2])]


def _rows(ids: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """(R,) int64 rows of the chunks ``ids`` (ascending), concatenated."""
    first, size = starts[ids], starts[ids + 1] - starts[ids]
    offset = np.repeat(first - np.concatenate([[0], np.cumsum(size)[:-1]]), size)
    return offset + np.arange(int(size.sum()))


def keys_order(keys: np.ndarray) -> np.ndarray:
    """The exact sort of :meth:`ChunkedCull.visible_keys`: (K,) uint32 scene indices front to
    back, ties by index (:func:`splatgl.order.sort.depth_sort`'s order)."""
    return np.sort(keys).view(np.uint32)[0::2].copy()


def keys_pairs(keys: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray]:
    """``(depth (K,) float32, indices (K,) uint32)`` of unsorted keys over a scene of ``count``
    splats, for the sorts that take depths and ascending indices (the device sort, the 16-bit
    bucket sort): the indices ascending, then the seam copies (index with
    :data:`splatgl.cameras.equirect.WRAP_FLAG`) ascending, as :func:`splatgl.order.lens_cull.lens_order` lists them.
    O(count): scatters into scene order, no sort."""
    words = keys.view(np.uint32).reshape(-1, 2)
    copy = words[:, 0] >= WRAP_FLAG
    depths, indices = [], []
    for part, flag in ((words[~copy], 0), (words[copy], WRAP_FLAG)):
        depth = np.zeros(count, np.uint32)
        seen = np.zeros(count, bool)
        index = part[:, 0] & ~WRAP_FLAG
        seen[index] = True
        depth[index] = part[:, 1]
        idx = np.flatnonzero(seen).astype(np.uint32)
        depths.append(depth[idx].view(np.float32))
        indices.append(idx | np.uint32(flag))
    return np.concatenate(depths), np.concatenate(indices)


def rows_keys(data: CullData, rows: np.ndarray, camera: Camera, near: float,
              antialias: bool = False, scale: float = 1.0, kern=None,
              out: np.ndarray | None = None) -> np.ndarray:
    """(K,) uint64 sort keys ``(float_bits(z) << 32) | row`` of the rows ``rows`` (ascending
    int64) of ``data`` that :func:`~splatgl.order.cull.cull_visible` keeps, in row order; ``kern``
    (:func:`splatgl.order.kernels.for_view`'s kernels, not with antialiasing) culls them in place
    without gathering them, else NumPy culls the gathered rows; ``out`` (at least ``rows.size``)
    is written to and a view of it returned."""
    keys = np.empty(rows.size, np.uint64) if out is None or out.size < rows.size else out
    if kern is None or antialias or camera.is_orthographic:
        idx, z = cull_visible(data.subset(rows), camera, near, antialias, scale)
        return depth_keys(z, rows[idx].astype(np.uint32), keys[:idx.size])
    peak = peak_constants(camera, scale)
    unsure = np.empty(UNSURE_ROWS, np.int64), np.empty((UNSURE_ROWS, 3), np.float32)
    xyz = data.xyz
    n, c = kern.rows_pass(rows, xyz[0], xyz[1], xyz[2], data.radius, data.alive, data.faint,
                          data.max_scale, data.opacities, camera.rotation.astype(np.float32),
                          camera.translation.astype(np.float32), plane_constants(frustum_of(camera), scale),
                          near_threshold(near, np.float32), peak, keys.view(np.uint32),
                          keys.view(np.float32), *unsure)
    if c > UNSURE_ROWS:  # too many undecided rows (almost never): NumPy culls the view
        return rows_keys(data, rows, camera, near, antialias, scale, None, out)
    at = rows[unsure[0][:c]]
    return keys[:settle_unsure(keys, n, at, at.astype(np.uint32), unsure[1][:c], data, camera,
                               scale)]


def peak_constants(camera: Camera, scale: float) -> np.ndarray:
    """(9,) float64 per-view constants of the compiled peak alpha bound: fx, fy, cx, cy, width,
    height, the Jacobian's clamps on x/z and y/z, and the radius scale."""
    tx, ty = camera.tan_half_fov
    return np.array([camera.fx, camera.fy, camera.cx, camera.cy, camera.width, camera.height,
                     JACOBIAN_CLAMP * tx, JACOBIAN_CLAMP * ty, scale], np.float64)


def settle_unsure(keys: np.ndarray, n: int, rows: np.ndarray, index: np.ndarray, p: np.ndarray,
                  data: CullData, camera: Camera, scale: float) -> int:
    """NumPy's peak bound on the rows ``rows`` of ``data`` that a compiled pass left undecided
    (camera-space points ``p``): the kept ones' keys (with scene indices ``index``) written to
    ``keys`` from ``n`` on; returns the new count."""
    if not rows.size:
        return n
    keep = peak_keeps(p, rows, data, camera, False, scale)
    k = int(keep.sum())
    depth_keys(p[keep, 2], index[keep], keys[n:n + k])
    return n + k
