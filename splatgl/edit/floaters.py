"""``--remove-floaters``: drop splats that are isolated in space and faint.

The statistical outlier test of point-cloud tools (PCL's StatisticalOutlierRemoval) on the
splat centres, gated by opacity:

1. for every splat, ``d`` = the mean distance to its ``neighbours`` nearest other centres
   (a k-d tree, :class:`scipy.spatial.cKDTree`, queried in blocks);
2. over the scene, the mean ``m`` and standard deviation ``s`` of ``d``;
3. a floater is a splat with ``d > m + sigma * s`` (isolated) **and** opacity below
   ``opacity`` (faint; 1 lets every isolated splat go).

Every parameter and the resulting threshold are printed (:meth:`Floaters.describe`).  The tree
holds the kept centres only (float64, about 50 bytes a splat with its index), the queries one
block of distances at a time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import SplatglError

#: Rows per k-d tree query block.
BLOCK = 1 << 17


@dataclass(frozen=True)
class RemoveFloaters:
    """Remove isolated, faint splats (see the module notes).

    Attributes:
        neighbours: k, the neighbours whose mean distance measures isolation (>= 1).
        sigma: standard deviations above the mean distance that count as isolated (> 0).
        opacity: only splats with opacity below this are removed (0-1; 1: all isolated ones).
    """

    neighbours: int = 16
    sigma: float = 3.0
    opacity: float = 0.5
    name = "remove-floaters"

    def __post_init__(self):
        if isinstance(self.neighbours, bool) or int(self.neighbours) != self.neighbours \
                or not 1 <= self.neighbours <= 256:
            raise SplatglError(f"--remove-floaters: neighbours must be an integer 1-256, got "
                               f"{self.neighbours!r}")
        if not (math.isfinite(self.sigma) and self.sigma > 0):
            raise SplatglError(f"--remove-floaters: sigma must be > 0, got {self.sigma!r}")
        if not (math.isfinite(self.opacity) and 0 < self.opacity <= 1):
            raise SplatglError(f"--remove-floaters: opacity must be in (0, 1], got "
                               f"{self.opacity!r}")
        object.__setattr__(self, "neighbours", int(self.neighbours))

    def find(self, means: np.ndarray, opacity: np.ndarray, progress=None) -> "Floaters":
        """Which of the splats with centres ``means`` (M, 3) and ``opacity`` (M,) are floaters."""
        from scipy.spatial import cKDTree

        finite = np.isfinite(means).all(axis=1)
        if not finite.all():  # NaN centres (a scene built in memory): not floaters, not in the tree
            found = self.find(means[finite], opacity[finite], progress)
            mask = np.zeros(means.shape[0], bool)
            mask[finite] = found.mask
            return Floaters(self, mask, found.mean, found.sd, found.threshold)
        m = means.shape[0]
        if m <= self.neighbours:
            return Floaters(self, np.zeros(m, bool), 0.0, 0.0, math.inf)
        tree = cKDTree(np.asarray(means, np.float64), balanced_tree=False, compact_nodes=False)
        dist = np.empty(m)
        if progress is not None:
            progress(0, m, "finding floaters")  # done == 0 starts the meter's clock
        for start in range(0, m, BLOCK):
            d, _ = tree.query(means[start:start + BLOCK], k=self.neighbours + 1, workers=-1)
            dist[start:start + BLOCK] = d[:, 1:].mean(axis=1)  # column 0: the splat itself
            if progress is not None:
                progress(min(start + BLOCK, m), m, "finding floaters")
        del tree
        mean, sd = float(dist.mean()), float(dist.std())
        threshold = mean + self.sigma * sd
        return Floaters(self, (dist > threshold) & (opacity < self.opacity), mean, sd, threshold)

    def describe(self) -> str:
        return (f"{self.neighbours} neighbours, mean distance > mean + {self.sigma:g} sd, "
                f"opacity < {self.opacity:g}")


@dataclass(frozen=True)
class Floaters:
    """What :meth:`RemoveFloaters.find` found: the (M,) mask and the statistics it used."""

    test: RemoveFloaters
    mask: np.ndarray = field(repr=False)
    mean: float
    sd: float
    threshold: float

    def describe(self) -> str:
        return (f"{self.test.describe()} (mean {self.mean:.4g}, sd {self.sd:.4g}: threshold "
                f"{self.threshold:.4g} world units)")

    def detail(self) -> str:
        """The step's note: the threshold and its statistics, or why nothing could be isolated."""
        if not math.isfinite(self.threshold):
            n = self.mask.size
            return (f"{n:,} splat{'' if n == 1 else 's'}, not more than the {self.test.neighbours} "
                    "neighbours: none can be isolated, none removed")
        return (f"threshold {self.threshold:.4g} world units (mean {self.mean:.4g} + "
                f"{self.test.sigma:g} x sd {self.sd:.4g})")
