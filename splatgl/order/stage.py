"""The order stage as the quad path uses it: a source of sorted rows per view.

A :class:`RowSource` turns a :class:`~splatgl.cameras.view.View` into the rows to draw, front to
back (and, for a level-of-detail cut, an opacity weight per sorted slot).  :class:`SceneOrder`
is the source of a plain scene: the view's cull (:data:`CULLS`) and the sort the settings
choose; the level-of-detail source is :class:`splatgl.lod.source.LodOrder`, which culls its
cut's rows and its leaves through the same table.  The quad path draws whatever a source gives.

:data:`CULLS` is the one place that maps a camera model's cull kind
(:attr:`View.frustum <splatgl.cameras.view.View.frustum>`) to the cull that runs: the planes'
chunked cull (:mod:`splatgl.order.chunks`; for a model with its own cull frustum, lens
distortion, :func:`splatgl.order.cull.cull_visible` on every row) for FRUSTUM and BOX, and the
lens cameras' :mod:`splatgl.order.lens_cull` for SPHERE.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, NamedTuple, Protocol

import numpy as np

from ..cameras.model import CullKind
from ..cameras.view import Frustum, View
from ..constants import JACOBIAN_CLAMP
from ..scene.splats import Scene
from ..scene.settings import RenderSettings, SortKey
from ..splatmath.project import to_camera
from .chunks import ChunkedCull, keys_order, keys_pairs, rows_keys
from .cull import CullData, cull_visible
from .lens_cull import lens_keys, lens_visible_keys
from .sort import bucket_sort, depth_keys, depth_sort

#: ``sort(depth (M,) float32, rows (M,) uint32) -> rows front to back``: the sort stage.
SortFn = Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass(frozen=True)
class OrderTimes:
    """Seconds of one view's order stage: ``cull`` (writing the sort keys included), ``sort``,
    and ``build`` (building the scene's chunked cull data, on the first culled view only)."""

    cull: float = 0.0
    sort: float = 0.0
    build: float = 0.0


class RowSource(Protocol):
    """What the quad path draws from (see the module doc)."""

    #: Rows of the scene the source indexes (the uploaded scene's count).
    count: int
    #: The last view's order stage times.
    times: OrderTimes
    #: The last view's opacity weight per sorted slot, (K,) float32, or None (all 1).
    slot_weights: np.ndarray | None

    def order(self, view: View) -> np.ndarray:
        """(K,) uint32 rows of the scene, front to back."""
        ...


def _planes_scene(chunks: ChunkedCull, view: View, antialias: bool,
                  ewa: bool = False) -> np.ndarray:
    scale = view.scale * (ewa_widening(view.frustum) if ewa else 1.0)
    if view.frustum.peak:
        return chunks.visible_keys(view.anchored, view.near, antialias, scale)
    # a model with its own cull frustum (lens distortion): every row against its planes
    idx, z = cull_visible(chunks.data, view.anchored, view.near, antialias, scale)
    return depth_keys(z, chunks.index[idx])


def ewa_widening(frustum: Frustum) -> float:
    """The factor on the world radii that makes the planes' cull keep every splat whose EWA
    footprint can reach alpha 1/255 on a pixel of the image (the conservative mode, which the
    CPU renderer runs: its image must be the one every row gives).

    A footprint's extent along x is ``k sqrt(Sxx + LOW_PASS)`` pixels, ``Sxx <= |J_x|^2 s^2``
    with ``|J_x| = f sqrt(1 + a^2) / z`` and ``a`` the slope ``x / z`` clamped inside the
    Jacobian (at most ``C = max(|lo|, |hi|) + (JACOBIAN_CLAMP - 1) / 2 (hi - lo)`` from the
    axis: a centred pinhole's ``JACOBIAN_CLAMP tan(half fov)``).  A splat past a side plane of
    slope ``e`` by ``d`` reaches ``d sqrt(1 + e^2) f / z`` pixels beyond the edge: the plane's
    test ``d <= r + MARGIN_PX z / f`` holds every such footprint once ``r`` is widened by
    ``sqrt(1 + C^2) / sqrt(1 + e^2)`` (the margin covers ``k sqrt(LOW_PASS)`` <= 1.83 px).  The
    sphere's own test (``r`` against the true slopes) can miss a large splat just past a wide
    image's edge, whose clamped Jacobian is steeper than the plane's slope.  1 for a BOX
    (orthographic: no clamp, ``|J_x| = f``)."""
    if frustum.kind is not CullKind.FRUSTUM:
        return 1.0
    factor = 1.0
    for _f, lo, hi in frustum.edges:
        c = max(abs(lo), abs(hi)) + 0.5 * (JACOBIAN_CLAMP - 1.0) * (hi - lo)
        factor = max(factor, np.sqrt((1.0 + c * c) / (1.0 + min(lo * lo, hi * hi))))
    return float(factor)


def _planes_rows(data: CullData, rows: np.ndarray, view: View, antialias: bool, kern=None,
                 out: np.ndarray | None = None) -> np.ndarray:
    return rows_keys(data, rows, view.anchored, view.near, antialias, view.scale,
                     kern if view.frustum.peak else None, out)


def _sphere_scene(chunks: ChunkedCull, view: View, antialias: bool,
                  ewa: bool = False) -> np.ndarray:   # the centre's rules alone: as conservative
    return lens_visible_keys(chunks, view.anchored, view.near, view.scale)


def _sphere_rows(data: CullData, rows: np.ndarray, view: View, antialias: bool, kern=None,
                 out: np.ndarray | None = None) -> np.ndarray:
    live = rows[data.alive[rows]]      # lens_keys takes drawable rows only, as chunks hold
    keys = np.empty(live.size, np.uint64) if out is None or out.size < live.size else out
    return lens_keys(data.subset(live), live.astype(np.uint32), keys, view.anchored, view.near,
                     view.scale, kern)[0]


class Cull(NamedTuple):
    """A cull of :data:`CULLS`; both give unsorted uint64 sort keys ``(float_bits(depth) << 32)
    | index`` (:func:`splatgl.order.sort.depth_keys`; an equirectangular seam copy's index with
    :data:`~splatgl.cameras.equirect.WRAP_FLAG`)."""

    #: ``(chunks, view, antialias, ewa=False)``: the splats of a scene's chunked cull data, by
    #: scene index; ``ewa``: the conservative mode (:func:`ewa_widening`).
    scene: Callable[..., np.ndarray]
    #: ``(data, rows, view, antialias, kern=None, out=None)``: the rows ``rows`` (ascending) of
    #: ``data`` (a level-of-detail cut's), by row; ``kern`` the compiled kernels or None,
    #: ``out`` a key buffer to write into.
    rows: Callable[..., np.ndarray]
    #: Whether it runs with ``settings.cull`` off too (its keys order by distance, not z).
    always: bool = False


#: The cull of each camera model's :class:`~splatgl.cameras.model.CullKind`: what the scene
#: order, the level-of-detail order and the CPU renderer run for a view (:func:`cull_for`).
CULLS: dict[CullKind, Cull] = {
    CullKind.FRUSTUM: Cull(_planes_scene, _planes_rows),
    CullKind.BOX: Cull(_planes_scene, _planes_rows),     # chunks.visible_keys takes the box
    CullKind.SPHERE: Cull(_sphere_scene, _sphere_rows, always=True),
}


def cull_for(view: View) -> Cull:
    """The cull of ``view``'s camera model (:data:`CULLS`)."""
    return CULLS[view.frustum.kind]


def cpu_sort(settings: RenderSettings) -> SortFn:
    """The CPU sort the settings choose: exact 32-bit depth keys, or 16-bit buckets."""
    return bucket_sort if settings.sort_key is SortKey.BUCKET16 else depth_sort


class SceneOrder:
    """The order stage of a plain scene (see the module doc).

    The order is reused while the view's :attr:`~splatgl.cameras.view.View.key` repeats; with
    ``settings.resort_interval`` N > 1 only every N-th change of view re-sorts (sort lag, for
    the benchmark).  ``sort``: the sort stage for settings other than the exact CPU sort (the
    device radix sort needs the GL context, which its owner holds).
    """

    def __init__(self, scene: Scene, settings: RenderSettings, sort: SortFn | None = None):
        self.scene = scene
        self.settings = settings
        self.count = scene.count
        self.sort = sort or cpu_sort(settings)
        self.chunks: ChunkedCull | None = None   # built on the first culled view
        self.times = OrderTimes()
        self.slot_weights: np.ndarray | None = None
        self._key: tuple | None = None
        self._order = np.zeros(0, np.uint32)
        self._stale = 0

    def order(self, view: View) -> np.ndarray:
        self.times = OrderTimes()
        if view.key == self._key:
            return self._order
        if self._key is not None and self._stale + 1 < self.settings.resort_interval:
            self._stale += 1
            self._key = view.key
            return self._order
        self._stale = 0
        cull = cull_for(view)
        build = 0.0
        if (cull.always or self.settings.cull) and self.chunks is None:
            tb = time.perf_counter()
            self.chunks = ChunkedCull.from_scene(self.scene)
            build = time.perf_counter() - tb
        t0 = time.perf_counter()
        if cull.always or self.settings.cull:
            keys = cull.scene(self.chunks, view, self.settings.antialias)
            t1 = time.perf_counter()
            if self.settings.sort_key is SortKey.EXACT:
                order = keys_order(keys)
            else:
                order = self.sort(*keys_pairs(keys, self.scene.count))
        else:
            p_cam = to_camera(self.scene.relative_means, view.anchored)
            keep = np.flatnonzero(p_cam[:, 2] > view.near).astype(np.uint32)  # keys need z > 0
            depth = p_cam[keep, 2]
            t1 = time.perf_counter()
            order = self.sort(depth, keep)
        t2 = time.perf_counter()
        self.times = OrderTimes(t1 - t0, t2 - t1, build)
        self._key, self._order = view.key, order
        return order
