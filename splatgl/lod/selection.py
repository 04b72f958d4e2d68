"""How a level-of-detail cut is chosen and drawn: its settings, the threshold cut with its switch
to the leaves, and the NumPy twin of its opacity weights (:func:`blended_scene`).  The quad
path draws a cut through :mod:`splatgl.lod.source`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..cameras.camera import Camera
from ..errors import SplatglError
from ..scene.splats import Scene
from .build import LodTree
from .cut import DEFAULT_BAND, DEFAULT_THRESHOLD_PX, CutData, level_leaves, select_cut_weights


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


def threshold_cut(tree: LodTree, data: CutData, camera: Camera, lod: LodSettings, kern=None,
                  max_nodes: int | None = None
                  ) -> tuple[np.ndarray | None, np.ndarray | None, float]:
    """The cut :class:`LodRenderer` draws for ``camera`` without a budget: ``(rows, weights,
    nodes per leaf)``, rows and weights as :func:`select_cut_weights` gives them, or ``(None,
    None, 1.0)`` when the view should draw the leaves instead (its cut stands for at most
    ``1 / SKIP_NODES_PER_LEAF`` leaves a node).  ``kern``: the compiled kernels
    (:func:`splatgl.order.kernels.for_view`), or None for NumPy: the same cut.  ``max_nodes``:
    :class:`splatgl.lod.cut.CutTooLarge` past it (:func:`select_cut_weights`)."""
    ids, weights = select_cut_weights(data, camera, lod.threshold_px, lod.band,
                                      leaves_at=SKIP_NODES_PER_LEAF, kern=kern, max_nodes=max_nodes)
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
