"""Rendering a level-of-detail cut through the quad path.

:class:`LodRenderer` is a :class:`splatgl.quad.QuadRenderer` over every node of a
:class:`splatgl.lod.build.LodTree` (leaves and merged parents, uploaded once); per view its
cull stage first selects the cut (:mod:`splatgl.lod.cut`), then culls and sorts only the cut's
nodes.  Everything after (pre-pass, draw, blending, read-back) is the quad path's own.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import moderngl
import numpy as np

from ..camera import Camera
from ..cull import CullData, cull_visible
from ..errors import SplatglError
from ..gl.shaders import ProgramCache
from ..project import anchored_camera
from ..quad import QuadRenderer
from ..settings import RenderSettings
from .build import LodTree
from .cut import DEFAULT_THRESHOLD_PX, CutData, select_cut, select_cut_budget


#: A cut with at least this share of leaves saves too little to pay for its own selection
#: (measured on the 6M scene: 90-95% leaves made frames up to 1.28x slower than full detail).
#: Views no farther from the scene than such a view then draw the leaves directly.
LEAF_SHARE_SKIP = 0.9


@dataclass(frozen=True)
class LodSettings:
    """How the cut is chosen.

    Attributes:
        threshold_px: nodes whose bounding sphere projects to at most this radius in pixels
            stand for their subtree (smaller: finer and slower).
        budget: at most this many nodes per view (the finest cut that fits, never finer than
            ``threshold_px``); None: no budget.
    """

    threshold_px: float = DEFAULT_THRESHOLD_PX
    budget: int | None = None

    def __post_init__(self) -> None:
        if not self.threshold_px > 0.0:
            raise SplatglError(f"--lod-threshold must be positive, got {self.threshold_px}")
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
        self.tree = tree
        self.lod = lod
        self.cut_data = CutData.from_tree(tree)
        self.last_cut_nodes = 0
        self.last_cut_s = 0.0
        self.last_threshold_px = lod.threshold_px
        #: Views at most this far from the root's centre draw the leaves (see LEAF_SHARE_SKIP).
        self.skip_within: float | None = None
        self._root = tree.nodes.means[-1].astype(np.float64)

    def visible_order(self, camera: Camera) -> np.ndarray:
        """Cut, cull and sort for ``camera``: (M,) uint32 node rows, front to back.

        Without a budget, a view no farther from the scene (the root's centre) than one whose
        cut was at least LEAF_SHARE_SKIP leaves skips the cut and culls the leaves (a contiguous
        view of the cull data): close views cost what full detail costs.
        """
        t0 = time.perf_counter()
        n_leaves = self.tree.level_size(0)
        dist = float(np.linalg.norm(camera.center - self._root))
        if self._cull_data is None:
            self._cull_data = CullData.from_scene(self.scene)
        if self.lod.budget is None and self.skip_within is not None and dist <= self.skip_within:
            keep, depth = cull_visible(self._cull_data.subset(slice(0, n_leaves)),
                                       anchored_camera(camera, self.scene.anchor), self.near,
                                       self.settings.antialias, camera.scale)
            t2 = time.perf_counter()
            order = self.sort_visible(depth, keep)
            self._times_cull, self._times_sort = t2 - t0, time.perf_counter() - t2
            self.last_cut_nodes, self.last_cut_s = n_leaves, 0.0
            self._order_key, self._order = None, order
            return order
        if self.lod.budget is not None:
            ids, self.last_threshold_px = select_cut_budget(self.cut_data, camera, self.lod.budget,
                                                            self.lod.threshold_px)
        else:
            ids = select_cut(self.cut_data, camera, self.lod.threshold_px)
        t1 = time.perf_counter()
        if ids.size and np.count_nonzero(ids < n_leaves) >= LEAF_SHARE_SKIP * ids.size:
            self.skip_within = max(self.skip_within or 0.0, dist)
        keep, depth = cull_visible(self._cull_data.subset(ids),
                                   anchored_camera(camera, self.scene.anchor), self.near,
                                   self.settings.antialias, camera.scale)
        keep = ids[keep].astype(np.uint32)  # ids ascending: ties still by row
        t2 = time.perf_counter()
        order = self.sort_visible(depth, keep)
        t3 = time.perf_counter()
        self._times_cull, self._times_sort = t2 - t0, t3 - t2
        self.last_cut_nodes, self.last_cut_s = int(ids.size), t1 - t0
        self._order_key, self._order = None, order
        return order
