"""Bottom-up hierarchy of a scene: groups of neighbouring splats merged into parents by moment
matching (as in the hierarchical 3DGS of Kerbl et al. 2024).

Neighbours: the leaves are put in Morton (Z-curve) order of their centres, so consecutive rows
are near each other; each level merges consecutive groups of ``branching`` nodes of the level
below into one parent.  The tree is therefore implicit: level ``l`` occupies rows
``offsets[l]:offsets[l + 1]`` of the node arrays, and node ``j`` of level ``l + 1`` has the
children ``j * B .. j * B + B - 1`` of level ``l`` (fewer at the end of a level).

Moment matching of a group with weights ``w_i = o_i * A_i`` (opacity times the ellipsoid's
surface-area proxy ``A = s1 s2 + s1 s3 + s2 s3``):

    mean      mu    = sum w_i mu_i / W
    covariance Sigma = sum w_i (Sigma_i + (mu_i - mu)(mu_i - mu)^T) / W
    SH        h     = sum w_i h_i / W
    opacity   o     = min(sum o_i A_i / A, ALPHA_MAX)  (the children's alpha mass spread over
                      the parent's area: a tight cluster of opaque splats stays opaque)

The parent's scales and rotation come from the eigen-decomposition of ``Sigma``.  Each node also
gets a bounding sphere (centre = its mean) that holds its own extent (``k(o) * max scale``, as
in the cull) and every child's sphere, so a node's projected size never falls below a child's
(what makes the per-view cut well defined, :mod:`splatgl.lod.cut`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..constants import ALPHA_MAX, ALPHA_MIN
from ..errors import SplatglError
from ..splatmath.project import covariance_3d, quat_to_rotmat
from ..scene.quaternion import rotmat_to_quat
from ..scene.splats import Scene
from ..scene.spatial import morton_order_clamped_box

#: Default number of children per parent.
BRANCHING = 4
#: Rows per block when the leaves' covariances are formed (float64 (M, 3, 3) temporaries).
BLOCK = 1 << 18
#: Log-scales above this give scales beyond float32 (inf), whose moments cannot be matched.
MAX_LOG_SCALE = 88


@dataclass(frozen=True)
class LodTree:
    """A scene's hierarchy.

    Attributes:
        nodes: every node as one :class:`Scene`: the leaves first (the original splats in Morton
            order), then each coarser level; the last level has a single root.
        offsets: (L + 1,) int64 row offsets of the levels in ``nodes``.
        branching: children per parent.
        leaf_order: (N,) int64 original row of each leaf.
        radius: (M,) float32 bounding-sphere radius of each node (world units), centred on its mean.
    """

    nodes: Scene
    offsets: np.ndarray
    branching: int
    leaf_order: np.ndarray
    radius: np.ndarray

    @property
    def levels(self) -> int:
        return len(self.offsets) - 1

    def level_size(self, level: int) -> int:
        return int(self.offsets[level + 1] - self.offsets[level])


def area_proxy(scales: np.ndarray) -> np.ndarray:
    """(M,) the ellipsoid's surface-area proxy ``s1 s2 + s1 s3 + s2 s3`` of (M, 3) scales."""
    return scales[:, 0] * scales[:, 1] + scales[:, 0] * scales[:, 2] + scales[:, 1] * scales[:, 2]


def _extent(opacity: np.ndarray, max_scale: np.ndarray) -> np.ndarray:
    """``k(o) * max_scale``: the radius within which alpha can reach 1/255 (as in the cull)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        k = np.sqrt(np.maximum(2.0 * np.log(np.maximum(opacity, 1e-30) / ALPHA_MIN), 0.0))
    return k * max_scale


def merge_groups(mu, cov, opac, area, sh, branching):
    """One level up: groups of ``branching`` consecutive rows -> parents, by the moment matching
    above (float64 arrays: means (M, 3), covariances (M, 3, 3), opacities (M,), areas (M,), SH
    (M, K, 3)).  Returns ``(means, covariances, opacities, areas, sh, scales, quats, owner)`` of
    the parents (``owner``: (M,) parent of each row).  The hierarchy's levels and
    :mod:`splatgl.edit.decimate` (pairs of neighbours) both merge through it."""
    n = mu.shape[0]
    starts = np.arange(0, n, branching)
    w = opac * area
    w = np.where(w > 0, w, 1e-30)  # a group of invisible children still gets a parent
    wsum = np.add.reduceat(w, starts)
    owner = np.arange(n) // branching
    p_mu = np.add.reduceat(w[:, None] * mu, starts) / wsum[:, None]
    d = mu - p_mu[owner]
    p_cov = np.add.reduceat(w[:, None, None] * (cov + d[:, :, None] * d[:, None, :]), starts)
    p_cov /= wsum[:, None, None]
    p_sh = np.add.reduceat(w[:, None, None] * sh, starts) / wsum[:, None, None]
    evals, evecs = np.linalg.eigh(p_cov)
    scales = np.sqrt(np.maximum(evals, 1e-30))
    evecs[np.linalg.det(evecs) < 0, :, 0] *= -1.0  # a proper rotation
    p_area = area_proxy(scales)
    p_opac = np.minimum(np.add.reduceat(opac * area, starts) / np.maximum(p_area, 1e-300), ALPHA_MAX)
    return p_mu, p_cov, p_opac, p_area, p_sh, scales, rotmat_to_quat(evecs), owner


def build_hierarchy(scene: Scene, branching: int = BRANCHING, progress=None) -> LodTree:
    """The hierarchy of ``scene`` (3DGS): leaves in Morton order, levels up to one root.

    ``progress(done_levels, total_levels, what)`` follows each level when given.
    """
    if branching < 2:
        raise ValueError(f"branching must be at least 2, got {branching}")
    for s in range(0, scene.count, BLOCK):  # NaN moments, then a LinAlgError, otherwise
        big = np.flatnonzero((scene.log_scales[s:s + BLOCK] > MAX_LOG_SCALE).any(axis=1))
        if big.size:
            raise SplatglError(f"level of detail: splat {s + int(big[0]):,} has a scale above "
                               f"e^{MAX_LOG_SCALE} world units, whose moments overflow: remove "
                               "such splats first (splatgl edit --remove 'max_scale > 1e38')")
    order = morton_order_clamped_box(scene.means.astype(np.float64))
    leaves = scene.subset(order)
    n = leaves.count
    total_levels = 1 + int(np.ceil(np.log(max(n, 1)) / np.log(branching)))
    mu, cov, opac, area, sh = leaf_moments(leaves)
    levels = []  # (means, quats, scales, opacity, sh) of each internal level
    while mu.shape[0] > 1:
        p_mu, p_cov, p_opac, p_area, p_sh, p_scales, p_quat, owner = merge_groups(mu, cov, opac, area, sh,
                                                                            branching)
        levels.append((p_mu, p_quat, p_scales, p_opac, p_sh))
        mu, cov, opac, area, sh = p_mu, p_cov, p_opac, p_area, p_sh
        if progress is not None:
            progress(len(levels) + 1, total_levels, "building levels")
    offsets = level_offsets(n, branching)
    nodes = concat_nodes(leaves, levels)
    return LodTree(nodes, offsets, branching, order.astype(np.int64),
                   bounding_radii(nodes, offsets, branching))


def leaf_moments(leaves: Scene):
    """The float64 ``(means, covariances, opacities, areas, sh)`` that :func:`merge_groups`
    merges, of the leaves (row by row: a chunk of leaves gets the values the whole would)."""
    n = leaves.count
    mu = leaves.means.astype(np.float64)
    opac = leaves.opacities.astype(np.float64)
    scales = leaves.scales.astype(np.float64)
    area = area_proxy(scales)
    sh = leaves.sh.astype(np.float64)
    cov = np.empty((n, 3, 3))
    for s in range(0, n, BLOCK):
        cov[s:s + BLOCK] = covariance_3d(quat_to_rotmat(leaves.rotations[s:s + BLOCK].astype(np.float64)),
                                         scales[s:s + BLOCK])
    return mu, cov, opac, area, sh


def level_offsets(n_leaves: int, branching: int) -> np.ndarray:
    """(L + 1,) int64 row offsets of the levels of a tree over ``n_leaves`` leaves."""
    sizes = [n_leaves]
    while sizes[-1] > 1:
        sizes.append(-(-sizes[-1] // branching))
    return np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)


def bounding_radii(nodes: Scene, offsets: np.ndarray, branching: int) -> np.ndarray:
    """(M,) float32 bounding-sphere radius of every node, centred on its mean: the largest of
    its own extent ``k(o) * max scale`` and ``|child mean - mean| + child radius`` over its
    children, level by level from the leaves up (so a parent's sphere holds its children's)."""
    return propagate_radii(nodes.means.astype(np.float64), own_extents(nodes), offsets,
                           branching).astype(np.float32)


def own_extents(nodes: Scene) -> np.ndarray:
    """(M,) float64 ``k(o) * max scale`` of each node: its sphere before its children's."""
    return _extent(nodes.opacities.astype(np.float64), nodes.scales.max(axis=1).astype(np.float64))


def propagate_radii(means: np.ndarray, radius: np.ndarray, offsets: np.ndarray,
                    branching: int) -> np.ndarray:
    """:func:`bounding_radii`'s pass from the leaves up over float64 ``means`` (M, 3) and
    ``radius`` (M,) (updated in place and returned): the out-of-core build runs it per chunk
    and then over the chunks' roots, with the same float64 values, so the radii are the same."""
    for level in range(len(offsets) - 2):
        lo, hi, top = offsets[level], offsets[level + 1], offsets[level + 2]
        owner = hi + np.arange(hi - lo) // branching
        child = np.linalg.norm(means[lo:hi] - means[owner], axis=1) + radius[lo:hi]
        radius[hi:top] = np.maximum(radius[hi:top],
                                    np.maximum.reduceat(child, np.arange(0, hi - lo, branching)))
    return radius


def concat_nodes(leaves: Scene, levels) -> Scene:
    """One Scene of the leaves' stored values followed by every internal level (activated
    values turned back into stored ones by :meth:`Scene.from_activated`)."""
    if not levels:
        return leaves
    mu = np.concatenate([lv[0] for lv in levels])
    quats = np.concatenate([lv[1] for lv in levels])
    scales = np.concatenate([lv[2] for lv in levels])
    opac = np.concatenate([lv[3] for lv in levels])
    sh = np.concatenate([lv[4] for lv in levels])
    inner = Scene.from_activated(mu, quats, scales, opac, sh)
    return Scene(np.concatenate([leaves.means, inner.means]),
                 np.concatenate([leaves.quats, inner.quats]),
                 np.concatenate([leaves.log_scales, inner.log_scales]),
                 np.concatenate([leaves.opacity_logits, inner.opacity_logits]),
                 np.concatenate([leaves.sh, inner.sh]))
