"""The in-memory scene: N activated Gaussians (3DGS) or surfels (2DGS).

Files store log-scales, opacity logits and unnormalised quaternions.  :func:`activate` is the one
place that turns those raw values into a :class:`Scene`, validating every row on the way.
"""

from __future__ import annotations

import enum
import functools
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..constants import MAX_LOGIT, MAX_SH_DEGREE, MIN_SCALE, sh_coeff_count
from ..errors import SceneFormatError, require
from .opacity import finite_logits

#: A quaternion whose norm is below this is treated as degenerate (no rotation can be derived).
MIN_QUAT_NORM = 1e-12


class InvalidRowsDropped(UserWarning):
    """The warning :func:`activate` gives when ``drop_invalid`` removed rows: ``dropped`` of
    ``total`` rows of the file ``path`` (what ``splatgl edit --drop-invalid`` counts)."""

    def __init__(self, path, dropped: int, total: int):
        super().__init__(f"{path}: dropped {dropped} invalid row(s) of {total}")
        self.path, self.dropped, self.total = path, dropped, total


class SplatKind(enum.Enum):
    """What each primitive is: a 3D Gaussian (3 scales) or a 2DGS surfel (2 scales)."""

    GAUSSIAN_3D = "3dgs"
    SURFEL_2D = "2dgs"


@dataclass(frozen=True)
class SceneSource:
    """The file a scene was read from and what its header says about it
    (:func:`splatgl.formats.scene_source`; :attr:`Scene.source`).

    Attributes:
        path: the file (as given to :func:`splatgl.load_scene`).
        antialias_tag: a short description of the tag marking the scene as trained with
            antialiasing (:func:`splatgl.formats.metadata.antialias_tag`), or None: such a
            scene renders with ``antialias`` on by default (:func:`splatgl.default_settings`).
    """

    path: Path
    antialias_tag: str | None = None


@dataclass(frozen=True)
class Scene:
    """N splats, stored as the file values; activated values are derived once, on first use.

    Stored (float32, C-contiguous, read-only; world space):
        means: (N, 3) centres in world units.
        quats: (N, 4) quaternions (w, x, y, z) as stored, not necessarily unit length.
        log_scales: (N, 3) natural-log standard deviations along the local axes; for surfels
            (N, 2), the two tangent axes.
        opacity_logits: (N,) logit of the opacity.
        sh: (N, K, 3) SH coefficients, K = (degree + 1)^2, coefficient-major with RGB last;
            ``sh[:, 0]`` is the DC term (``f_dc``).
        kind: 3DGS Gaussians or 2DGS surfels.
        source: the file the scene was read from and its tags (:class:`SceneSource`), set by
            :func:`splatgl.load_scene`; None for a scene built in memory (a subset, a
            transformed copy).  It gives the scene's defaults: its training cameras' up
            (:func:`splatgl.default_camera`) and antialiasing (:func:`splatgl.default_settings`).
        extras: the file's other per-splat properties (a PLY's ``nx ny nz``, a ``label``): a
            (N,) structured array of their stored types, or None; :meth:`subset` and the edit
            operations keep them with their rows, the PLY writer writes them.

    Keeping the raw values makes a PLY written from a scene read back bit-identical.  The
    activations (exp scale, sigmoid opacity, normalised quaternion) live in the three cached
    properties :attr:`scales`, :attr:`opacities` and :attr:`rotations`, and nowhere else.
    Build scenes with :func:`activate`-checked loaders or :meth:`from_activated`.
    """

    means: np.ndarray
    quats: np.ndarray
    log_scales: np.ndarray
    opacity_logits: np.ndarray
    sh: np.ndarray
    kind: SplatKind = SplatKind.GAUSSIAN_3D
    source: SceneSource | None = field(default=None, compare=False, repr=False)
    extras: np.ndarray | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        n = np.shape(self.means)[0]
        nscale = 2 if self.kind is SplatKind.SURFEL_2D else 3
        expect = {"means": (n, 3), "quats": (n, 4), "log_scales": (n, nscale), "opacity_logits": (n,)}
        for name, shape in expect.items():
            if np.shape(getattr(self, name)) != shape:
                raise ValueError(
                    f"Scene.{name} has shape {np.shape(getattr(self, name))}, expected {shape}"
                )
        sh_shape = np.shape(self.sh)
        if len(sh_shape) != 3 or sh_shape[0] != n or sh_shape[2] != 3:
            raise ValueError(f"Scene.sh has shape {sh_shape}, expected ({n}, K, 3)")
        if sh_shape[1] not in [sh_coeff_count(d) for d in range(MAX_SH_DEGREE + 1)]:
            raise ValueError(f"Scene.sh has {sh_shape[1]} coefficients per channel")
        if self.extras is not None and (self.extras.shape != (n,) or self.extras.dtype.names is None):
            raise ValueError(f"Scene.extras must be a ({n},) structured array")
        for name in ("means", "quats", "log_scales", "opacity_logits", "sh"):
            if _adoptable(getattr(self, name)):
                continue  # a loader's read-only float32 array: nothing can change it, no copy
            arr = np.array(getattr(self, name), dtype=np.float32, order="C", copy=True)
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)

    @classmethod
    def from_activated(cls, means: np.ndarray, rotations: np.ndarray, scales: np.ndarray,
                       opacities: np.ndarray, sh: np.ndarray,
                       kind: SplatKind = SplatKind.GAUSSIAN_3D) -> "Scene":
        """A scene from activated values (unit or raw quaternions, scales > 0, opacity in [0, 1]).

        Opacities of exactly 0 or 1 are stored as logits of +-40 (sigmoid(40) rounds to 1.0 in
        float32), so every stored value stays finite.
        """
        o = np.clip(np.asarray(opacities, np.float64), 0.0, 1.0)
        with np.errstate(divide="ignore"):
            logits = np.clip(np.log(o) - np.log1p(-o), -MAX_LOGIT, MAX_LOGIT)
        scales64 = np.maximum(np.asarray(scales, np.float64), MIN_SCALE)
        return cls(means, rotations, np.log(scales64), logits, sh, kind)

    def __repr__(self) -> str:
        """One line: count, kind, SH degree and the file's name (the arrays stay out)."""
        source = "" if self.source is None else f", source {Path(self.source.path).name!r}"
        return f"Scene({self.count:,} splats, {self.kind.value}, SH degree {self.sh_degree}{source})"

    @property
    def count(self) -> int:
        return int(self.means.shape[0])

    @property
    def sh_degree(self) -> int:
        return int(round(np.sqrt(self.sh.shape[1]))) - 1

    @functools.cached_property
    def scales(self) -> np.ndarray:
        """(N, 3) or (N, 2) float32 activated scales ``exp(log_scales)``, world units."""
        return _frozen(activate_scales(self.log_scales))

    @functools.cached_property
    def opacities(self) -> np.ndarray:
        """(N,) float32 activated opacities ``sigmoid(opacity_logits)`` in [0, 1].

        0 for rows whose quaternion is degenerate (see :attr:`rotations`): renderers skip them.
        """
        return _frozen(activate_opacities(self.opacity_logits, self.quats))

    @functools.cached_property
    def rotations(self) -> np.ndarray:
        """(N, 4) float32 unit quaternions (w, x, y, z), normalised in float64.

        Rows with a degenerate quaternion get the identity (never NaN; their opacity is 0).
        """
        return _frozen(activate_rotations(self.quats))

    def activated_rows(self, start: int, stop: int) -> "ActivatedRows":
        """Rows ``start:stop`` activated (the same values as :attr:`relative_means`,
        :attr:`opacities`, :attr:`rotations`, :attr:`scales`), computed now and not cached:
        what uploads and per-scene precomputations walk in chunks, so a large scene never holds
        a second full-size activated copy."""
        rows = slice(start, stop)
        return ActivatedRows(
            (self.means[rows].astype(np.float64) - self.anchor).astype(np.float32),
            activate_opacities(self.opacity_logits[rows], self.quats[rows]).astype(np.float32),
            activate_rotations(self.quats[rows]).astype(np.float32),
            activate_scales(self.log_scales[rows]).astype(np.float32))

    @functools.cached_property
    def anchor(self) -> np.ndarray:
        """(3,) float64 point amid the splats (the robust box centre, a float32 value), which
        every renderer subtracts from the means before float32 math (see :attr:`relative_means`
        and :func:`splatgl.splatmath.project.anchored_camera`); zeros when the means are not finite."""
        lo, hi = self.robust_bounds
        centre = (0.5 * (lo + hi)).astype(np.float32).astype(np.float64)
        out = centre if np.isfinite(centre).all() else np.zeros(3)
        out.flags.writeable = False
        return out

    @functools.cached_property
    def relative_means(self) -> np.ndarray:
        """(N, 3) float32 ``means - anchor``, subtracted in float64 (what the GPU is given)."""
        return _frozen(self.means.astype(np.float64) - self.anchor)

    @functools.cached_property
    def robust_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) float64 (3,) percentile bounds (1st..99th) of the means, ignoring strays."""
        if self.count == 0:
            return np.zeros(3), np.zeros(3)
        lo = np.percentile(self.means, 1.0, axis=0).astype(np.float64)
        hi = np.percentile(self.means, 99.0, axis=0).astype(np.float64)
        return lo, hi

    @property
    def robust_radius(self) -> float:
        """Half the diagonal of :attr:`robust_bounds` (world units); 0 for a single point."""
        lo, hi = self.robust_bounds
        return float(0.5 * np.linalg.norm(hi - lo))

    def subset(self, rows: np.ndarray) -> "Scene":
        """A new scene with only ``rows`` (boolean mask or index array)."""
        return Scene(
            self.means[rows], self.quats[rows], self.log_scales[rows], self.opacity_logits[rows],
            self.sh[rows], self.kind, extras=None if self.extras is None else self.extras[rows],
        )

    def with_sh_degree(self, degree: int) -> "Scene":
        """The scene truncated (or zero-padded) to SH ``degree``."""
        k = sh_coeff_count(degree)
        sh = self.sh[:, :k]
        if sh.shape[1] < k:
            sh = np.concatenate([sh, np.zeros((self.count, k - sh.shape[1], 3), np.float32)], 1)
        return Scene(self.means, self.quats, self.log_scales, self.opacity_logits, sh, self.kind,
                     extras=self.extras)


def require_scene(value, caller: str, reads: tuple[str, ...] = ()):
    """``value`` if it is a :class:`Scene` (or, where ``reads`` is given, has those attributes:
    a streamed scene's framing proxy); else a TypeError naming ``caller``, what it was given
    and how to load a scene.  The public functions taking a scene call it first."""
    return require(value, Scene, caller, "scene",
                   "a splatgl Scene (load one with splatgl.load_scene(path))", reads)


def _adoptable(arr) -> bool:
    """A float32 C-contiguous array that owns its data and is read-only (safe to share)."""
    return (isinstance(arr, np.ndarray) and arr.dtype == np.float32 and arr.flags.c_contiguous
            and arr.flags.owndata and not arr.flags.writeable)


def _frozen(arr: np.ndarray) -> np.ndarray:
    out = np.ascontiguousarray(arr, dtype=np.float32)
    out.flags.writeable = False
    return out


@dataclass(frozen=True)
class ActivatedRows:
    """A chunk of activated rows (float32): ``relative_means`` (M, 3) (``means - anchor``),
    ``opacities`` (M,), ``rotations`` (M, 4) unit (w, x, y, z), ``scales`` (M, 3) or (M, 2)."""

    relative_means: np.ndarray
    opacities: np.ndarray
    rotations: np.ndarray
    scales: np.ndarray


def activate_scales(log_scales: np.ndarray) -> np.ndarray:
    """(N, S) float64 ``exp(log_scales)`` (world units); inf beyond float32's range, so the
    float32 copies hold inf without NumPy's overflow warning (as for a log-scale of 1000)."""
    with np.errstate(over="ignore"):
        out = np.exp(log_scales.astype(np.float64))
    return np.where(out > np.finfo(np.float32).max, np.inf, out)


def rotation_ok(quats: np.ndarray) -> np.ndarray:
    """(N,) bool: the quaternion's norm is finite and at least MIN_QUAT_NORM."""
    q = quats.astype(np.float64)
    with np.errstate(over="ignore", invalid="ignore"):
        norm = np.sqrt((q * q).sum(axis=1))
    return np.isfinite(norm) & (norm >= MIN_QUAT_NORM)


def activate_opacities(logits: np.ndarray, quats: np.ndarray) -> np.ndarray:
    """(N,) float64 ``sigmoid(logits)``, 0 where the quaternion is degenerate.

    Guard (stress case zero_quats): a Scene built directly (not through the loaders) can hold
    zero or sub-1e-12 quaternions; no rotation, hence no covariance, exists for them, and a
    1e-30 quaternion rendered as the identity (max error 0.75).  Opacity 0 makes every renderer
    skip the row (cull, alpha < 1/255) without a special case anywhere.
    """
    with np.errstate(over="ignore"):
        o = 1.0 / (1.0 + np.exp(-logits.astype(np.float64)))
    return np.where(rotation_ok(quats), o, 0.0)


def activate_rotations(quats: np.ndarray) -> np.ndarray:
    """(N, 4) float64 unit quaternions; the identity where the quaternion is degenerate."""
    q = quats.astype(np.float64)
    ok = rotation_ok(quats)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        unit = q / np.sqrt((q * q).sum(axis=1, keepdims=True))
    return np.where(ok[:, None], unit, [1.0, 0.0, 0.0, 0.0])


def sh_degree_from_rest_count(path: object, n_rest: int) -> int:
    """SH degree from the number of ``f_rest_*`` properties (0, 9, 24 or 45)."""
    for degree in range(MAX_SH_DEGREE + 1):
        if n_rest == 3 * (sh_coeff_count(degree) - 1):
            return degree
    raise SceneFormatError(
        path, f"{n_rest} properties found; expected 0, 9, 24 or 45 (SH degree 0-3)", "f_rest_*"
    )


def rest_to_sh(dc: np.ndarray, rest: np.ndarray) -> np.ndarray:
    """Assemble (N, K, 3) SH from ``f_dc`` (N, 3) and channel-major ``f_rest`` (N, 3 * (K - 1)).

    ``f_rest`` holds all red coefficients first, then green, then blue.
    """
    n = dc.shape[0]
    k1 = rest.shape[1] // 3
    sh = np.empty((n, k1 + 1, 3), np.float32)
    sh[:, 0] = dc
    sh[:, 1:] = rest.reshape(n, 3, k1).transpose(0, 2, 1)
    return sh


def sh_to_rest(sh: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`rest_to_sh`: ``(f_dc (N, 3), f_rest (N, 3 * (K - 1)))``."""
    n = sh.shape[0]
    return sh[:, 0].copy(), sh[:, 1:].transpose(0, 2, 1).reshape(n, 3 * (sh.shape[1] - 1)).copy()


def _report_bad(path, field, bad: np.ndarray, what: str, drop: bool, dropped: np.ndarray) -> None:
    if not bad.any():
        return
    count = int(bad.sum())
    first = int(np.flatnonzero(bad)[0])
    if not drop:
        raise SceneFormatError(
            path, f"{count} row(s) {what} (first at index {first}); "
            "use --drop-invalid to drop them", field
        )
    dropped |= bad


#: Rows per block of the validation in :func:`activate` (its temporaries, such as float64
#: quaternions or an (N, 48) mask, exist for one block at a time, not for the whole scene).
VALIDATE_BLOCK = 1 << 16


def _rows_where(arr: np.ndarray, test) -> np.ndarray:
    """(N,) bool ``test(block)`` evaluated over blocks of VALIDATE_BLOCK rows of ``arr``."""
    out = np.empty(arr.shape[0], bool)
    for start in range(0, arr.shape[0], VALIDATE_BLOCK):
        out[start:start + VALIDATE_BLOCK] = test(arr[start:start + VALIDATE_BLOCK])
    return out


def activate(path: object, means: np.ndarray, quats: np.ndarray, log_scales: np.ndarray,
             opacity_logits: np.ndarray, sh: np.ndarray, kind: SplatKind = SplatKind.GAUSSIAN_3D,
             drop_invalid: bool = False, extras: np.ndarray | None = None) -> Scene:
    """Validate raw file values and build the :class:`Scene` (the one entry point for loaders).

    Rows with NaN/Inf in any field or a zero/degenerate quaternion are invalid.  By default an
    invalid row is an error (:class:`SceneFormatError` naming file, field, count and first
    index); with ``drop_invalid`` such rows are removed and a warning counts them.  An empty
    scene is always an error.

    Args:
        path: the file the values came from (for messages).
        means: (N, 3) world positions.  quats: (N, 4) raw (w, x, y, z).
        log_scales: (N, 3) or (N, 2) natural-log scales.  opacity_logits: (N,).
        sh: (N, K, 3) SH coefficients.
    """
    n = means.shape[0]
    if n == 0:
        raise SceneFormatError(path, "the scene has no splats")
    dropped = np.zeros(n, bool)
    opacity_logits = finite_logits(path, opacity_logits)   # +-Inf: opacity exactly 1 or 0
    fields = {
        "position": means, "rotation": quats, "scale": log_scales,
        "opacity": opacity_logits.reshape(n, 1), "sh": sh.reshape(n, -1),
    }
    for name, arr in fields.items():
        _report_bad(path, name, _rows_where(arr, lambda a: ~np.isfinite(a).all(axis=1)),
                    "hold NaN or Inf", drop_invalid, dropped)

    def degenerate(q: np.ndarray) -> np.ndarray:
        q64 = q.astype(np.float64)
        with np.errstate(invalid="ignore", over="ignore"):
            norms = np.sqrt((q64 * q64).sum(axis=1))
        return np.isfinite(norms) & (norms < MIN_QUAT_NORM)

    _report_bad(path, "rotation", _rows_where(quats, degenerate),
                "have a zero or degenerate quaternion", drop_invalid, dropped)
    if dropped.any():
        keep = ~dropped
        warnings.warn(InvalidRowsDropped(path, int(dropped.sum()), n), stacklevel=2)
        if not keep.any():
            raise SceneFormatError(path, f"all {n} rows are invalid; nothing left to render")
        means, quats, log_scales = means[keep], quats[keep], log_scales[keep]
        opacity_logits, sh = opacity_logits[keep], sh[keep]
        extras = None if extras is None else extras[keep]
    return Scene(means, quats, log_scales, opacity_logits, sh, kind, extras=extras)
