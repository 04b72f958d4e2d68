"""The row-selecting edit operations: crops, value filters, invalid rows, SH bands.

Each selecting operation answers ``keep(rows)`` for one block of rows
(:class:`~splatgl.edit.attributes.Rows`), so a 6M-splat scene is tested a block at a time
(:mod:`splatgl.edit.pipeline` runs them).  Definitions, exactly (tested against
splat-transform where it has the same operation, see docs/editing.md):

- :class:`CropBox` keeps a splat whose centre lies in the box, faces included
  (``lo <= p <= hi`` on every axis), in the scene's own coordinates (those of the file, after a
  merge's ``--transform``); with ``transform`` the box is placed by it (box frame to scene), i.e.
  the test is on ``transform^-1(p)``.
- :class:`CropSphere` keeps a splat whose centre is strictly inside: ``|p - c|^2 < r^2``
  (float64 from the stored float32 means, the squares summed x, y, z in that order).
- :class:`Filter` keeps the splats where its expression (:mod:`splatgl.edit.expression`) holds.
- ``invert`` on any of them keeps the others instead.
- :class:`DropInvalid` drops rows holding NaN or +-Inf in any stored value, or a quaternion whose
  norm is below 1e-12 (the loaders' ``--drop-invalid`` rule).
- :class:`ShDegree` keeps SH bands up to ``degree`` (never adds bands).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..constants import MAX_SH_DEGREE
from ..errors import SplatglError
from ..scene.splats import MIN_QUAT_NORM, Scene, SplatKind
from ..scene.transform import SceneTransform
from .attributes import ATTRIBUTES, Rows
from .expression import Expression, parse_expression


def _vec(values, n: int, what: str, infinite: bool = False) -> tuple[float, ...]:
    """``n`` floats of ``values``; finite ones (or, with ``infinite``, anything but NaN)."""
    try:
        out = tuple(float(v) for v in values)
    except (TypeError, ValueError, OverflowError):
        raise SplatglError(f"{what}: expected {n} numbers, got {values!r}") from None
    if len(out) != n:
        raise SplatglError(f"{what}: expected {n} numbers, got {len(out)}")
    if not all(math.isfinite(v) or (infinite and not math.isnan(v)) for v in out):
        kind = "a number or +-inf, not NaN" if infinite else "finite"
        raise SplatglError(f"{what}: every number must be {kind}, got {values!r}")
    return out


def _fmt(values) -> str:
    return ",".join(f"{v:g}" for v in values)


@dataclass(frozen=True)
class CropBox:
    """Keep the splats inside the box ``lo``..``hi`` (world units, faces included), placed by
    ``transform`` (box frame to scene; None: axis-aligned); ``invert`` keeps those outside."""

    lo: tuple
    hi: tuple
    transform: SceneTransform | None = None
    invert: bool = False
    name = "crop-box"

    def __post_init__(self):
        lo = _vec(self.lo, 3, "--crop-box min", infinite=True)
        hi = _vec(self.hi, 3, "--crop-box max", infinite=True)
        for axis, a, b in zip("xyz", lo, hi):
            if a > b:
                raise SplatglError(f"--crop-box: min {axis} {a:g} > max {axis} {b:g}: the box "
                                   "is empty (give X0,Y0,Z0,X1,Y1,Z1 with X0 <= X1 ...)")
        object.__setattr__(self, "lo", lo)
        object.__setattr__(self, "hi", hi)

    def keep(self, rows: Rows) -> np.ndarray:
        p = rows.means
        if self.transform is not None and not self.transform.is_identity:
            t = self.transform
            with np.errstate(over="ignore", invalid="ignore"):  # far beyond the box: outside
                p = (p - np.asarray(t.translation)) @ np.asarray(t.rotation) / t.scale
        inside = ((p >= self.lo) & (p <= self.hi)).all(axis=1)
        return inside != self.invert

    def describe(self) -> str:
        placed = "" if self.transform is None or self.transform.is_identity else ", placed"
        return f"{'outside' if self.invert else 'inside'} box {_fmt(self.lo)} .. {_fmt(self.hi)}{placed}"


@dataclass(frozen=True)
class CropSphere:
    """Keep the splats strictly inside the sphere (``centre``, ``radius`` > 0, world units);
    ``invert`` keeps those outside or on it."""

    centre: tuple
    radius: float
    invert: bool = False
    name = "crop-sphere"

    def __post_init__(self):
        centre = _vec(self.centre, 3, "--crop-sphere centre")
        if not (isinstance(self.radius, (int, float)) and math.isfinite(self.radius)
                and self.radius > 0):
            raise SplatglError(f"--crop-sphere: the radius must be a finite number > 0, got "
                               f"{self.radius!r}")
        object.__setattr__(self, "centre", centre)
        object.__setattr__(self, "radius", float(self.radius))

    def keep(self, rows: Rows) -> np.ndarray:
        d = rows.means - np.asarray(self.centre)
        with np.errstate(over="ignore"):  # squares beyond float64: inf, compared as such
            inside = (d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2]
                      < np.square(np.float64(self.radius)))
        return inside != self.invert

    def describe(self) -> str:
        return (f"{'outside' if self.invert else 'inside'} sphere centre {_fmt(self.centre)} "
                f"radius {self.radius:g}")


@dataclass(frozen=True)
class Filter:
    """Keep the splats where ``expression`` holds (text or a parsed
    :class:`~splatgl.edit.expression.Expression`); ``invert`` removes them instead."""

    expression: Expression | str
    invert: bool = False
    name = "filter"

    def __post_init__(self):
        if isinstance(self.expression, str):
            object.__setattr__(self, "expression", parse_expression(self.expression,
                                                                    self.option))

    @property
    def option(self) -> str:
        """The command-line option of this filter: ``--remove`` when inverted."""
        return "--remove" if self.invert else "--filter"

    def check(self, scene: Scene) -> None:
        """Refuse attributes the scene's kind lacks (scale_2 of 2DGS surfels)."""
        if scene.kind is SplatKind.SURFEL_2D:
            bad = sorted(n for n in self.expression.names if not ATTRIBUTES[n].surfels)
            if bad:
                raise SplatglError(f"{self.option} {self.expression.text!r}: 2DGS surfels have "
                                   f"no {', '.join(bad)} (two scales only)")

    def keep(self, rows: Rows) -> np.ndarray:
        return self.expression.evaluate(rows) != self.invert

    def describe(self) -> str:
        return f"{'remove where' if self.invert else 'keep where'} {self.expression.text}"


@dataclass(frozen=True)
class DropInvalid:
    """Drop rows with NaN/Inf in any stored value or a (near-)zero quaternion."""

    name = "drop-invalid"

    def keep(self, rows: Rows) -> np.ndarray:
        s, r = rows.scene, rows.rows
        ok = np.isfinite(s.means[r]).all(axis=1) & np.isfinite(s.quats[r]).all(axis=1)
        ok &= np.isfinite(s.log_scales[r]).all(axis=1) & np.isfinite(s.opacity_logits[r])
        ok &= np.isfinite(s.sh[r]).all(axis=(1, 2))
        q = s.quats[r].astype(np.float64)
        with np.errstate(over="ignore", invalid="ignore"):
            ok &= np.sqrt((q * q).sum(axis=1)) >= MIN_QUAT_NORM
        return ok

    def describe(self) -> str:
        return "NaN/Inf values or zero quaternions"


@dataclass(frozen=True)
class ShDegree:
    """Keep SH bands up to ``degree`` (0-3); a scene with fewer keeps what it has."""

    degree: int
    name = "sh-degree"

    def __post_init__(self):
        if isinstance(self.degree, bool) or not isinstance(self.degree, (int, np.integer)) \
                or not 0 <= self.degree <= MAX_SH_DEGREE:
            raise SplatglError(f"--sh-degree must be an integer 0-{MAX_SH_DEGREE}, got "
                               f"{self.degree!r}")

    def describe(self) -> str:
        return f"SH bands up to degree {self.degree}"


#: The operations that keep or drop rows block by block.
ROW_TESTS = (CropBox, CropSphere, Filter, DropInvalid)
