"""Rendering a level-of-detail cut through the quad path.

:class:`LodRenderer` is a :class:`splatgl.renderers.quad.QuadRenderer` over every node of a
:class:`splatgl.lod.build.LodTree` (leaves and merged parents, uploaded once); per view its
cull stage first selects the cut (:mod:`splatgl.lod.cut`), then culls and sorts only the cut's
nodes.  With a transition band the cut's nodes carry opacity weights: they go to the device
as one float per sorted slot, which the compute pre-pass applies to the opacity as a factor on
its optical depth, ``1 - (1 - o) ** w`` (shaders/quad_prepass.comp, OPACITY_WEIGHT).  Everything after (draw, blending, read-back) is
the quad path's own.  NumPy twin of the weighting: :func:`blended_scene`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import moderngl
import numpy as np

from ..order import kernels as cull_kernel
from ..background import Background
from ..cameras.camera import Camera
from ..order.cull import CullData, cull_visible
from ..order.chunks import ChunkedCull, keys_order, keys_pairs, rows_keys
from ..errors import SplatglError
from ..gl.shaders import ProgramCache
from ..cameras.view import anchored_camera
from ..renderers.quad import BINDING_OPACITY_WEIGHT, QuadRenderer
from ..model.scene import Scene
from ..model.settings import RenderSettings, SortKey
from .build import LodTree
from .cut import (DEFAULT_BAND, DEFAULT_THRESHOLD_PX, CutData, level_leaves, select_cut_budget,
                  select_cut_weights)


#: A cut that draws at least this many nodes per leaf it stands for saves too little to pay for
#: its own selection (measured on the 6M scene: cuts of 90-95% leaves, about 0.77-0.87 nodes a
#: leaf, made frames up to 1.28x slower than full detail).  Such a view, and every view no
#: farther from the scene, draws the leaves directly, culled as full detail culls them.
SKIP_NODES_PER_LEAF = 0.75
#: From this many nodes per leaf on, the leaves' chunked cull is built in the background, ready
#: for the switch (on the 1M scene the cut reaches 0.5 about 1.6x farther out than the switch).
PREFETCH_NODES_PER_LEAF = 0.5


@dataclass(frozen=True)
class LodSettings:
    """How the cut is chosen.

    Attributes:
        threshold_px: nodes whose bounding sphere projects to at most this radius in pixels
            stand for their subtree (smaller: finer and slower).
        budget: at most this many nodes per view (the finest cut that fits, never finer than
            ``threshold_px``); None: no budget.
        band: transition band, a ratio >= 1: nodes projecting to between ``threshold_px`` and
            ``band * threshold_px`` are drawn as a blend of themselves and their children
            (opacity weights, :func:`splatgl.lod.cut.select_cut_weights`), so the image changes
            continuously along a path; 1: the plain cut (a node switches to its children at
            once).  Needs the compute pre-pass (the default ``preprocess``).
    """

    threshold_px: float = DEFAULT_THRESHOLD_PX
    budget: int | None = None
    band: float = DEFAULT_BAND

    def __post_init__(self) -> None:
        if not self.threshold_px > 0.0:
            raise SplatglError(f"--lod-threshold must be positive, got {self.threshold_px}")
        if not (self.band >= 1.0 and np.isfinite(self.band)):
            raise SplatglError(f"--lod-blend must be a ratio of at least 1 (1: no blending), "
                               f"got {self.band}")
        if self.budget is not None and self.budget < 1:
            raise SplatglError(f"--lod-budget must be at least 1, got {self.budget}")


class LodRenderer(QuadRenderer):
    """The quad path over a LOD tree's nodes, drawing a per-view cut.

    After each view: ``last_cut_nodes`` (nodes in the cut), ``last_cut_s`` (seconds the cut
    selection took; also counted in the frame's ``cull`` time) and ``last_threshold_px``.
    """

    def __init__(self, ctx: moderngl.Context, tree: LodTree, settings: RenderSettings,
                 lod: LodSettings = LodSettings(), programs: ProgramCache | None = None):
        super().__init__(ctx, tree.nodes, settings, programs)
        if lod.band > 1.0 and not self.uses_prepass:
            raise SplatglError(f"--lod-blend {lod.band:g} weights opacities in the compute "
                               "pre-pass: use --preprocess compute (the default), or --lod-blend 1")
        self.tree = tree
        self.lod = lod
        self.cut_data = CutData.from_tree(tree)
        self.last_cut_nodes = 0
        self.last_cut_s = 0.0
        self.last_threshold_px = lod.threshold_px
        #: The last view drew the leaves instead of a cut (see SKIP_NODES_PER_LEAF).
        self.last_drew_leaves = False
        #: Views at most this far from the root's centre draw the leaves (see SKIP_NODES_PER_LEAF).
        self.skip_within: float | None = None
        self._root = tree.nodes.means[-1].astype(np.float64)
        #: This view's opacity weight per sorted slot, (K,) float32, or None (all 1).
        self.slot_weights: np.ndarray | None = None
        self._node_weight: np.ndarray | None = None  # (M,) scratch: weight by node row
        #: The last view's cut, (rows, weights or None); the leaves when it skipped the cut.
        self.last_cut: tuple[np.ndarray, np.ndarray | None] | None = None
        #: Draw this cut, (rows ascending, weights or None), instead of selecting one per view.
        self.cut_override: tuple[np.ndarray, np.ndarray | None] | None = None
        self._weight_buffer = None
        self._leaf_chunks: ChunkedCull | None = None  # the leaves' chunked cull
        #: Builds the leaves' chunked cull in the background once a view's cut comes near the
        #: switch (PREFETCH_NODES_PER_LEAF), so that the view that switches to the leaves does
        #: not stall on it (about 1 s at 3M splats), and far views never pay for it.
        self._leaf_build: Background | None = None
        self._views = 0  # views so far (the compiled kernels are requested from the second on)
        self._cut_keys: np.ndarray | None = None  # (>= K,) uint64 key buffer of the cut's cull

    def visible_order(self, camera: Camera) -> np.ndarray:
        """Cut, cull and sort for ``camera``: (M,) uint32 node rows, front to back.

        Without a budget, a view whose cut stands for at most 1 / SKIP_NODES_PER_LEAF leaves a
        node (:func:`leaves_covered`), and from then on every view no farther from the scene
        (the root's centre), draws the leaves instead, culled by chunks as full detail is:
        close views cost what full detail costs (plus, on the view that decides, the cut's
        selection).  With ``cut_override`` set to
        ``(rows, weights)`` (an earlier view's ``last_cut``) that cut is drawn instead: what the
        benchmark compares against to measure the change the cut alone makes between frames.
        """
        t0 = time.perf_counter()
        self._times_build = 0.0
        dist = float(np.linalg.norm(camera.center - self._root))
        if self._cull_data is None:
            self._cull_data = CullData.from_scene(self.scene)
        override = self.cut_override
        self._views += 1
        kern = cull_kernel.for_view(self._views)  # compiled selection and cull, once loaded
        if (override is None and self.lod.budget is None and self.skip_within is not None
                and dist <= self.skip_within):
            return self._leaves_order(camera, t0)
        if override is not None:
            ids, weights = override
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
            order = self._leaves_order(camera, t1)
            self.last_cut_s = t1 - t0
            self._times_cull += t1 - t0
            return order
        if self._cut_keys is None or self._cut_keys.size < ids.size:
            self._cut_keys = np.empty(ids.size, np.uint64)
        keys = rows_keys(self._cull_data, ids, anchored_camera(camera, self.scene.anchor),
                         self.near, self.settings.antialias, camera.scale,
                         kern, self._cut_keys)
        t2 = time.perf_counter()
        order = (keys_order(keys) if self.settings.sort_key is SortKey.EXACT  # ties by row
                 else self.sort_visible(*keys_pairs(keys, self.scene.count)))
        self.slot_weights = None
        if weights is not None and (weights < 1).any():
            if self._node_weight is None:
                self._node_weight = np.ones(self.scene.count, np.float32)
            self._node_weight[ids] = weights  # only the kept rows are read back
            self.slot_weights = self._node_weight[order]  # into sorted order
        t3 = time.perf_counter()
        self._times_cull, self._times_sort = t2 - t0, t3 - t2
        self.last_cut_nodes, self.last_cut_s = int(ids.size), t1 - t0
        self.last_drew_leaves = False
        self.last_cut = (ids, weights)
        self._order_key, self._order = None, order
        return order

    def _leaves_order(self, camera: Camera, t0: float) -> np.ndarray:
        """Cull and sort the leaves alone (full detail) for ``camera``; stage times from ``t0``.

        Pinhole views use the leaves' chunked cull (built on first use, timed as
        ``cull_build``), as :class:`QuadRenderer` does for a plain scene; lens views the
        per-splat cull of the leaves' rows (a contiguous view of the cull data)."""
        n_leaves = self.tree.level_size(0)
        leaves = self._cull_data.subset(slice(0, n_leaves))
        anchored = anchored_camera(camera, self.scene.anchor)
        if camera.is_lens:
            keep, depth = cull_visible(leaves, anchored, self.near, self.settings.antialias,
                                       camera.scale)
            t2 = time.perf_counter()
            order = self.sort_visible(depth, keep)
        else:
            if self._leaf_chunks is None:
                tb = time.perf_counter()  # waits for the background build, or builds here
                self._leaf_chunks = (self._leaf_build.result() if self._leaf_build is not None
                                     else ChunkedCull(leaves))
                self._times_build = time.perf_counter() - tb
                t0 += self._times_build
            keys = self._leaf_chunks.visible_keys(anchored, self.near, self.settings.antialias,
                                                  camera.scale)
            t2 = time.perf_counter()
            order = (keys_order(keys) if self.settings.sort_key is SortKey.EXACT
                     else self.sort_visible(*keys_pairs(keys, self.scene.count)))
        self._times_cull, self._times_sort = t2 - t0, time.perf_counter() - t2
        self.last_cut_nodes, self.last_cut_s = n_leaves, 0.0
        self.last_drew_leaves = True
        self._order_key, self._order, self.slot_weights = None, order, None
        self.last_cut = (np.arange(n_leaves), None)
        return order

    # ------------------------------------------------------------------ opacity weights
    def defines(self, camera: Camera, depth: bool = False) -> dict[str, object]:
        defines = super().defines(camera, depth)
        if self.slot_weights is not None:
            defines["OPACITY_WEIGHT"] = 1
        return defines

    def _upload(self, order: np.ndarray, prog=None) -> None:
        """The sorted rows, and this view's opacity weights (one float per slot) if any."""
        super()._upload(order, prog)
        w = self.slot_weights
        if w is None:
            return
        data = w.tobytes()
        if self._weight_buffer is None or self._weight_buffer.size < max(len(data), 4):
            if self._weight_buffer is not None:
                self._weight_buffer.release()
            self._weight_buffer = self.ctx.buffer(reserve=max(len(data), 4))
        if data:
            self._weight_buffer.write(data)

    def _prepass(self, camera: Camera, count: int, depth: bool) -> None:
        if self.slot_weights is not None:
            self._weight_buffer.bind_to_storage_buffer(BINDING_OPACITY_WEIGHT)
        super()._prepass(camera, count, depth)

    def release(self) -> None:
        if self._weight_buffer is not None:
            self._weight_buffer.release()
            self._weight_buffer = None
        super().release()


def threshold_cut(tree: LodTree, data: CutData, camera: Camera, lod: LodSettings, kern=None
                  ) -> tuple[np.ndarray | None, np.ndarray | None, float]:
    """The cut :class:`LodRenderer` draws for ``camera`` without a budget: ``(rows, weights,
    nodes per leaf)``, rows and weights as :func:`select_cut_weights` gives them, or ``(None,
    None, 1.0)`` when the view should draw the leaves instead (its cut stands for at most
    ``1 / SKIP_NODES_PER_LEAF`` leaves a node).  ``kern``: the compiled kernels
    (:func:`splatgl.order.kernels.for_view`), or None for NumPy: the same cut."""
    ids, weights = select_cut_weights(data, camera, lod.threshold_px, lod.band,
                                      leaves_at=SKIP_NODES_PER_LEAF, kern=kern)
    if ids is None:
        return None, None, 1.0
    covered = leaves_covered(tree, ids, weights) if ids.size else 0.0
    per_leaf = ids.size / covered if covered > 0 else 0.0
    if ids.size and per_leaf >= SKIP_NODES_PER_LEAF:
        return None, None, 1.0
    return ids, weights, per_leaf


def leaves_covered(tree: LodTree, rows: np.ndarray, weights: np.ndarray | None) -> float:
    """How many leaves the cut ``rows`` (ascending, weights as :func:`select_cut_weights` gives)
    stands for: each node's weight times the leaves under it (``branching ** level``, fewer for
    a level's last node; :func:`splatgl.lod.cut.level_leaves`).  Weights along a path sum to 1,
    so this counts the leaves in view whatever the band."""
    bounds = np.searchsorted(rows, tree.offsets)  # rows are sorted: per-level ranges
    total = 0.0
    for level in range(tree.levels):
        lo, hi = bounds[level], bounds[level + 1]
        total += level_leaves(tree.offsets, tree.branching, level,
                              rows[lo:hi] - int(tree.offsets[level]),
                              None if weights is None else weights[lo:hi])
    return total


def blended_scene(tree: LodTree, rows: np.ndarray, weights: np.ndarray | None) -> Scene:
    """NumPy twin of the opacity weights: the cut's nodes ``rows`` as a plain :class:`Scene`
    with each opacity ``o`` replaced by ``1 - (1 - o) ** w``, which any renderer draws as the
    pre-pass draws the weighted cut."""
    sub = tree.nodes.subset(rows)
    if weights is None:
        return sub
    o = 1.0 - (1.0 - sub.opacities.astype(np.float64)) ** weights.astype(np.float64)
    return Scene.from_activated(sub.means, sub.quats, sub.scales, o, sub.sh, sub.kind)
