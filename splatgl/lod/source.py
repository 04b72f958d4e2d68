"""A level-of-detail cut as the quad path's source of rows.

:class:`LodOrder` is a :class:`~splatgl.order.stage.RowSource` over every node of a
:class:`splatgl.lod.build.LodTree` (leaves and merged parents, uploaded once as
``tree.nodes``): per view it first selects the cut (:mod:`splatgl.lod.cut`, which tests the
view's frustum), then culls and sorts only the cut's nodes through the view's cull
(:func:`splatgl.order.stage.cull_for`, as a plain scene's order does: a lens camera's by
distance, with a panorama's seam copies).  With a transition band the cut's nodes carry opacity weights: one
float per sorted slot (:attr:`LodOrder.slot_weights`), which the quad path's compute pre-pass
applies to the opacity as a factor on its optical depth, ``1 - (1 - o) ** w``
(shaders/quad_prepass.comp, OPACITY_WEIGHT).  Everything after (draw, blending, read-back) is
the quad path's own: :func:`lod_renderer` puts the two together.  NumPy twin of the weighting:
:func:`splatgl.lod.selection.blended_scene`.
"""

from __future__ import annotations

import time

import moderngl
import numpy as np

from ..background import Background
from ..cameras.view import View
from ..errors import SplatglError
from ..gl.shaders import ProgramCache
from ..scene.settings import RenderSettings, SortKey
from ..order import kernels as cull_kernel
from ..order.chunks import ChunkedCull, keys_order, keys_pairs
from ..order.cull import CullData
from ..order.stage import OrderTimes, SortFn, cpu_sort, cull_for
from ..renderers.quad import QuadRenderer
from .build import LodTree
from .cut import CutData
from .cut_budget import select_cut_budget, select_cut_budget_near
from .selection import PREFETCH_NODES_PER_LEAF, LodSettings, threshold_cut


class LodOrder:
    """The rows of a per-view cut of ``tree`` (see the module doc).

    After each view: ``last_cut_nodes`` (nodes in the cut), ``last_cut_s`` (seconds the cut
    selection took; also counted in the frame's ``cull`` time), ``last_threshold_px``,
    ``last_drew_leaves`` and ``last_cut``.  Views at most :attr:`skip_within` from the root's
    centre draw the leaves (see :data:`splatgl.lod.selection.SKIP_NODES_PER_LEAF`);
    :attr:`cut_override` ``(rows, weights)`` draws that cut instead of selecting one (the
    benchmark's measure of the change the cut alone makes between frames).
    """

    def __init__(self, tree: LodTree, settings: RenderSettings, lod: LodSettings = LodSettings(),
                 sort: SortFn | None = None):
        self.tree = tree
        self.settings = settings
        self.lod = lod
        self.scene = tree.nodes
        self.count = tree.nodes.count
        self.sort = sort or cpu_sort(settings)
        self.cut_data = CutData.from_tree(tree)
        self.times = OrderTimes()
        self.slot_weights: np.ndarray | None = None
        self.last_cut_nodes = 0
        self.last_cut_s = 0.0
        self.last_threshold_px = lod.threshold_px
        #: Search a budget's cut from the last view's threshold (:func:`select_cut_budget_near`;
        #: interactive views, where consecutive frames are near).  Off: every view searches from
        #: the floor, so a path's frames do not depend on the frames before them.
        self.warm_start = False
        self.last_drew_leaves = False
        self.skip_within: float | None = None
        self.last_cut: tuple[np.ndarray, np.ndarray | None] | None = None
        self.cut_override: tuple[np.ndarray, np.ndarray | None] | None = None
        self._root = tree.nodes.means[-1].astype(np.float64)
        self._cull_data: CullData | None = None
        self._node_weight: np.ndarray | None = None  # (M,) scratch: weight by node row
        self._leaf_chunks: ChunkedCull | None = None  # the leaves' chunked cull
        #: Builds the leaves' chunked cull in the background once a view's cut comes near the
        #: switch (PREFETCH_NODES_PER_LEAF), so that the view that switches to the leaves does
        #: not stall on it (about 1 s at 3M splats), and far views never pay for it.
        self._leaf_build: Background | None = None
        self._views = 0  # views so far (the compiled kernels are requested from the second on)
        self._cut_keys: np.ndarray | None = None  # (>= K,) uint64 key buffer of the cut's cull

    def _sorted(self, keys: np.ndarray) -> np.ndarray:
        return (keys_order(keys) if self.settings.sort_key is SortKey.EXACT   # ties by row
                else self.sort(*keys_pairs(keys, self.count)))

    def order(self, view: View) -> np.ndarray:
        """Cut, cull and sort for ``view``: (M,) uint32 node rows, front to back.

        Without a budget, a view whose cut stands for at most 1 / SKIP_NODES_PER_LEAF leaves a
        node (:func:`splatgl.lod.selection.leaves_covered`), and from then on every view no
        farther from the scene (the root's centre), draws the leaves instead, culled by chunks
        as full detail is: close views cost what full detail costs (plus, on the view that
        decides, the cut's selection).
        """
        t0 = time.perf_counter()
        camera = view.camera   # the cut tests its frustum (splatgl.cameras.view.frustum_of)
        dist = float(np.linalg.norm(camera.center - self._root))
        if self._cull_data is None:
            self._cull_data = CullData.from_scene(self.scene)
        override = self.cut_override
        self._views += 1
        kern = cull_kernel.for_view(self._views)  # compiled selection and cull, once loaded
        if (override is None and self.lod.budget is None and self.skip_within is not None
                and dist <= self.skip_within):
            return self._leaves_order(view, t0)
        if override is not None:
            ids, weights = override
        elif self.lod.budget is not None and self.warm_start and self._views > 1:
            ids, weights, self.last_threshold_px = select_cut_budget_near(
                self.cut_data, camera, self.lod.budget, self.last_threshold_px,
                self.lod.threshold_px, self.lod.band, kern)
        elif self.lod.budget is not None:
            ids, weights, self.last_threshold_px = select_cut_budget(
                self.cut_data, camera, self.lod.budget, self.lod.threshold_px, self.lod.band, kern)
        else:
            ids, weights, per_leaf = threshold_cut(self.tree, self.cut_data, camera, self.lod, kern)
            if per_leaf >= PREFETCH_NODES_PER_LEAF and self._leaf_build is None:
                leaves = self._cull_data.subset(slice(0, self.tree.level_size(0)))
                self._leaf_build = Background(ChunkedCull, leaves, name="splatgl-lod-leaves")
        t1 = time.perf_counter()
        if ids is None:
            self.skip_within = max(self.skip_within or 0.0, dist)
            order = self._leaves_order(view, t1)
            self.last_cut_s = t1 - t0
            self.times = OrderTimes(self.times.cull + t1 - t0, self.times.sort, self.times.build)
            return order
        if self._cut_keys is None or self._cut_keys.size < ids.size:
            self._cut_keys = np.empty(ids.size, np.uint64)
        keys = cull_for(view).rows(self._cull_data, ids, view, self.settings.antialias, kern,
                                   self._cut_keys)
        t2 = time.perf_counter()
        order = self._sorted(keys)
        self.slot_weights = None
        if weights is not None and (weights < 1).any():
            if self._node_weight is None:
                self._node_weight = np.ones(self.count, np.float32)
            self._node_weight[ids] = weights  # only the kept rows are read back
            self.slot_weights = self._node_weight[order]  # into sorted order
        t3 = time.perf_counter()
        self.times = OrderTimes(t2 - t0, t3 - t2, 0.0)
        self.last_cut_nodes, self.last_cut_s = int(ids.size), t1 - t0
        self.last_drew_leaves = False
        self.last_cut = (ids, weights)
        return order

    def _leaves_order(self, view: View, t0: float) -> np.ndarray:
        """Cull and sort the leaves alone (full detail) for ``view``; stage times from ``t0``.

        The leaves' chunked cull (built on first use, timed as ``build``) through the view's
        cull (:func:`splatgl.order.stage.cull_for`), as a plain scene's order does."""
        n_leaves = self.tree.level_size(0)
        build = 0.0
        if self._leaf_chunks is None:
            tb = time.perf_counter()  # waits for the background build, or builds here
            self._leaf_chunks = (self._leaf_build.result() if self._leaf_build is not None
                                 else ChunkedCull(self._cull_data.subset(slice(0, n_leaves))))
            build = time.perf_counter() - tb
            t0 += build
        keys = cull_for(view).scene(self._leaf_chunks, view, self.settings.antialias)
        t2 = time.perf_counter()
        order = self._sorted(keys)
        self.times = OrderTimes(t2 - t0, time.perf_counter() - t2, build)
        self.last_cut_nodes, self.last_cut_s = n_leaves, 0.0
        self.last_drew_leaves = True
        self.slot_weights = None
        self.last_cut = (np.arange(n_leaves), None)
        return order


def lod_renderer(ctx: moderngl.Context, tree: LodTree, settings: RenderSettings,
                 lod: LodSettings = LodSettings(), programs: ProgramCache | None = None
                 ) -> QuadRenderer:
    """The quad path over ``tree``'s nodes, drawing a per-view cut (its :attr:`QuadRenderer.rows`
    is the :class:`LodOrder`, with the cut's statistics)."""
    quad = QuadRenderer(ctx, tree.nodes, settings, programs, rows=_Deferred())
    if lod.band > 1.0 and not quad.uses_prepass:
        quad.release()
        raise SplatglError(f"--lod-blend {lod.band:g} weights opacities in the compute "
                           "pre-pass: use --preprocess compute (the default), or --lod-blend 1")
    quad.rows = LodOrder(tree, settings, lod, quad.sort)
    return quad


class _Deferred:
    """Placeholder rows until :func:`lod_renderer` installs the cut's (it needs the quad
    renderer's sort)."""

    count = 0
    times = OrderTimes()
    slot_weights = None
