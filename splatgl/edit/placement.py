"""Moving a scene's splats into the world (baking a :class:`SceneTransform`) and merging scenes.

Baking ``p_w = s R p + t`` into the stored values (what rendering with ``--transform`` shows,
DESIGN.md section 1, now held in the file): means ``s R p + t``, quaternions ``q_R q`` (their
norms kept, so a zero quaternion stays invalid), log-scales ``+ log s``, and the SH rotated so
that each splat shows the same colour in every world direction: band ``l``'s coefficients are
multiplied by the ``(2l+1) x (2l+1)`` matrix ``B_l`` with ``Y_l(R^T d) = B_l^T Y_l(d)``, solved
exactly (least squares on 64 directions, a square system's solution) from
:func:`splatgl.splatmath.project.sh_basis`, so it follows splatgl's own SH convention by
construction.  Opacity is unchanged.

Merging (:func:`merge_scenes`): the scenes' rows one after another, in input order, each placed
by its own transform, into one scene that renders with one global sort.  SH degree rule: the
merged scene has the highest degree of the inputs (or ``sh_degree`` when given); inputs with
fewer bands get zero coefficients for the missing ones (zero bands add no colour: they render
exactly as before) and inputs with more are truncated.  3DGS and 2DGS scenes cannot be merged.
"""

from __future__ import annotations

import functools

import numpy as np

from ..constants import sh_coeff_count
from ..errors import SplatglError, require
from ..scene.quaternion import quat_multiply, rotmat_to_quat
from ..scene.splats import Scene, require_scene
from ..scene.transform import SceneTransform, transform_from_object
from ..splatmath.project import sh_basis

#: Rows per block while baking (float64 temporaries of one block at a time).
BLOCK = 1 << 18


@functools.lru_cache(maxsize=None)
def _directions() -> np.ndarray:
    """(64, 3) unit directions on a Fibonacci sphere (fixed: the solve is exact for any set)."""
    i = np.arange(64) + 0.5
    z = 1.0 - 2.0 * i / 64
    phi = np.pi * (1.0 + 5.0 ** 0.5) * i
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], 1)


def sh_rotation(rotation: np.ndarray, degree: int) -> np.ndarray:
    """(K, K) float64 block-diagonal matrix ``M`` (K = (degree + 1)^2): a splat turned by
    ``rotation`` (3x3) has the coefficients ``M @ h`` (``h``: its (K, 3) coefficients), i.e.
    its colour along ``d`` is the old colour along ``R^T d``."""
    rot = np.asarray(rotation, np.float64)
    dirs = _directions()
    before = sh_basis(dirs, degree)            # Y(d)
    after = sh_basis(dirs @ rot, degree)       # Y(R^T d): the old colour seen along d
    k = sh_coeff_count(degree)
    out = np.zeros((k, k))
    out[0, 0] = 1.0
    for band in range(1, degree + 1):
        s = slice(sh_coeff_count(band - 1), sh_coeff_count(band))
        b, *_ = np.linalg.lstsq(before[:, s], after[:, s], rcond=None)  # Y(R^T d) = Y(d) b
        out[s, s] = b
    return out


def transform_scene(scene: Scene, transform: SceneTransform | None,
                    what: str = "transform") -> Scene:
    """``scene`` with ``transform`` baked into its stored values (see the module notes); the
    same scene when the transform is None or the identity.  A transform that moves a splat
    beyond what float32 holds is refused (:class:`SplatglError` naming ``what``).  A dict
    with ``--transform``'s keys (``{"translate": [1, 0, 0]}``) is read as that option reads
    its JSON (:func:`splatgl.scene.transform.transform_from_object`)."""
    require_scene(scene, "transform_scene")
    if isinstance(transform, dict):
        transform = transform_from_object(transform, what)
    if transform is not None:
        require(transform, SceneTransform, "transform_scene", "transform",
                "a SceneTransform (SceneTransform.from_euler(...)), a dict with --transform's "
                "keys, or None")
    if transform is None or transform.is_identity:
        return scene
    n = scene.count
    means = np.empty((n, 3), np.float32)
    quats = np.empty((n, 4), np.float32)
    sh = np.empty_like(scene.sh)
    rot = np.asarray(transform.rotation, np.float64)
    q_rot = rotmat_to_quat(rot[None])[0]
    m_sh = sh_rotation(rot, scene.sh_degree)
    for start in range(0, n, BLOCK):
        rows = slice(start, start + BLOCK)
        with np.errstate(over="ignore", invalid="ignore"):
            placed = transform.apply_points(scene.means[rows])
        _check_float32(placed, start, scene.means[rows], transform, what)
        means[rows] = placed
        with np.errstate(over="ignore", invalid="ignore"):  # beyond float32: refused by edit
            quats[rows] = quat_multiply(q_rot, scene.quats[rows].astype(np.float64))
            sh[rows] = np.einsum("kj,njc->nkc", m_sh, scene.sh[rows].astype(np.float64))
    log_scales = (scene.log_scales.astype(np.float64) + np.log(transform.scale)).astype(np.float32)
    return Scene(_frozen(means), _frozen(quats), _frozen(log_scales), scene.opacity_logits,
                 _frozen(sh), scene.kind, extras=_turned_extras(scene.extras, rot))


def _turned_extras(extras: np.ndarray | None, rot: np.ndarray) -> np.ndarray | None:
    """A scene's other per-splat properties after a turn by ``rot``: its normals (``nx ny nz``)
    turn with the splats, the rest is kept as it is."""
    axes = ("nx", "ny", "nz")
    if extras is None or not set(axes) <= set(extras.dtype.names):
        return extras
    out = extras.copy()
    turned = np.stack([extras[a].astype(np.float64) for a in axes], axis=1) @ rot.T
    for i, a in enumerate(axes):
        out[a] = turned[:, i]
    return out


def shared_extras(scenes) -> np.dtype | None:
    """The other per-splat properties every one of ``scenes`` has (same name and type), which a
    merge keeps; None when they share none."""
    names = None
    for scene in scenes:
        own = [] if scene.extras is None else [(n, scene.extras.dtype[n])
                                               for n in scene.extras.dtype.names]
        names = own if names is None else [f for f in names if f in own]
    return np.dtype(names) if names else None


def describe_transform(transform: SceneTransform) -> str:
    """``rotate 90 deg, scale 2, translate 1,0,0`` (the parts that are not the identity)."""
    rot = np.asarray(transform.rotation)
    angle = float(np.degrees(np.arccos(np.clip((np.trace(rot) - 1.0) / 2.0, -1.0, 1.0))))
    parts = [f"rotate {angle:.4g} deg"] if angle > 0 else []
    parts += [f"scale {transform.scale:g}"] if transform.scale != 1 else []
    parts += ([f"translate {','.join(f'{v:g}' for v in transform.translation)}"]
              if any(transform.translation) else [])
    return ", ".join(parts) or "identity"


#: The largest finite float32: positions beyond it are infinite in the file.
FLOAT32_MAX = float(np.finfo(np.float32).max)


def _check_float32(placed: np.ndarray, start: int, before: np.ndarray, transform, what: str):
    """Refuse positions that float32 cannot hold (they would be stored as infinities)."""
    bad = ~(np.abs(placed) <= FLOAT32_MAX).all(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        was = ",".join(f"{v:.4g}" for v in before[i])
        raise SplatglError(f"{what} ({describe_transform(transform)}) moves splat {start + i:,} "
                           f"(at {was}) beyond float32's range (|coordinate| <= 3.4e38): its "
                           "position would be infinite")


def _frozen(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False
    return a


def merged_sh_degree(degrees, sh_degree: int | None = None) -> int:
    """The merged scene's SH degree: ``sh_degree`` if given, else the highest of ``degrees``."""
    return max(degrees) if sh_degree is None else sh_degree


def merge_scenes(scenes, transforms=None, sh_degree: int | None = None) -> Scene:
    """One scene holding every row of ``scenes`` in order, each placed by its transform
    (``transforms``: one :class:`SceneTransform` or None per scene), SH degree by the rule in the
    module notes.  A single scene without a transform is returned as it is."""
    scenes = list(scenes)
    transforms = list(transforms) if transforms is not None else [None] * len(scenes)
    if not scenes:
        raise SplatglError("merge: no scenes given")
    if len(transforms) != len(scenes):
        raise SplatglError(f"merge: {len(transforms)} transform(s) for {len(scenes)} scene(s)")
    kinds = {s.kind for s in scenes}
    if len(kinds) > 1:
        raise SplatglError("merge: cannot merge 3DGS Gaussians with 2DGS surfels")
    degree = merged_sh_degree([s.sh_degree for s in scenes], sh_degree)
    if len(scenes) == 1 and degree == scenes[0].sh_degree:
        return transform_scene(scenes[0], transforms[0])
    builder = MergeBuilder(sum(s.count for s in scenes), degree, scenes[0].kind,
                           shared_extras(scenes))
    for scene, transform in zip(scenes, transforms):
        builder.add(transform_scene(scene, transform))
    return builder.scene()


class MergeBuilder:
    """Fills one merged scene's arrays input by input, so a caller that loads the inputs one at
    a time holds one input and the merged arrays, never every input at once."""

    def __init__(self, count: int, sh_degree: int, kind, extras: np.dtype | None = None):
        self.k = sh_coeff_count(sh_degree)
        self.kind = kind
        self.means = np.empty((count, 3), np.float32)
        self.quats = np.empty((count, 4), np.float32)
        nscale = 2 if kind.value == "2dgs" else 3
        self.log_scales = np.empty((count, nscale), np.float32)
        self.opacity_logits = np.empty(count, np.float32)
        self.sh = np.zeros((count, self.k, 3), np.float32)
        self.extras = None if extras is None else np.empty(count, extras)  # shared_extras()
        self.filled = 0

    def add(self, scene: Scene) -> None:
        if scene.kind is not self.kind:
            raise SplatglError("merge: cannot merge 3DGS Gaussians with 2DGS surfels")
        rows = slice(self.filled, self.filled + scene.count)
        self.means[rows] = scene.means
        self.quats[rows] = scene.quats
        self.log_scales[rows] = scene.log_scales
        self.opacity_logits[rows] = scene.opacity_logits
        k = min(self.k, scene.sh.shape[1])
        self.sh[rows, :k] = scene.sh[:, :k]
        for name in self.extras.dtype.names if self.extras is not None else ():
            self.extras[name][rows] = scene.extras[name]
        self.filled += scene.count

    def scene(self) -> Scene:
        arrays = [self.means, self.quats, self.log_scales, self.opacity_logits, self.sh]
        for a in arrays:
            a.flags.writeable = False
        return Scene(*arrays, self.kind, extras=self.extras)
