"""The per-splat attributes ``--filter`` expressions and ``info --stats`` see, with their units.

Every attribute is computed from a block of stored rows (:class:`Rows`), never from the whole
scene at once, so filters over a 6M-splat scene hold one block's float64 temporaries only.
Values are decoded (activated) unless the name says raw: positions and scales in world units,
opacity in 0-1, colours in 0-1 (the SH DC term as a colour, ``0.5 + SH_C0 f_dc``).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..constants import SH_C0, sh_coeff_count
from ..scene.splats import Scene, activate_opacities


@dataclass(frozen=True)
class Attribute:
    """One per-splat value: ``name``, its ``unit`` (for help and statistics) and how it is
    computed from a :class:`Rows` block ((M,) float64)."""

    name: str
    unit: str
    compute: Callable[["Rows"], np.ndarray]
    #: The scene kinds it exists for (scale_2 does not exist for 2DGS surfels).
    surfels: bool = True
    #: Whether ``info --stats`` summarises it (not the row number).
    statistic: bool = True


class Rows:
    """Rows ``start:stop`` of a scene, with the decoded values computed once per block;
    ``first``: the input row of the scene's row 0 (a block of a streamed input,
    :mod:`splatgl.edit.streamed`), which ``index`` adds."""

    def __init__(self, scene: Scene, start: int, stop: int, first: int = 0):
        self.scene, self.start, self.stop = scene, start, stop
        self.rows = slice(start, stop)
        self.first = first

    @functools.cached_property
    def means(self) -> np.ndarray:
        return self.scene.means[self.rows].astype(np.float64)

    @functools.cached_property
    def log_scales(self) -> np.ndarray:
        return self.scene.log_scales[self.rows].astype(np.float64)

    @functools.cached_property
    def scales(self) -> np.ndarray:
        with np.errstate(over="ignore"):
            return np.exp(self.log_scales)

    @functools.cached_property
    def opacity(self) -> np.ndarray:
        return activate_opacities(self.scene.opacity_logits[self.rows], self.scene.quats[self.rows])

    @functools.cached_property
    def sh(self) -> np.ndarray:
        return self.scene.sh[self.rows]


def _effective_sh_degree(r: Rows) -> np.ndarray:
    """Highest SH band holding a nonzero coefficient (0: view-independent colour)."""
    out = np.zeros(r.stop - r.start)
    for degree in range(1, r.scene.sh_degree + 1):
        band = r.sh[:, sh_coeff_count(degree - 1):sh_coeff_count(degree)]
        out[(band != 0).any(axis=(1, 2))] = degree
    return out


def _attributes() -> dict[str, Attribute]:
    table = [
        Attribute("index", "the splat's row in the input, from 0 (as splatgl pixel lists it)",
                  lambda r: np.arange(r.first + r.start, r.first + r.stop, dtype=np.float64),
                  statistic=False),
        Attribute("x", "world units", lambda r: r.means[:, 0]),
        Attribute("y", "world units", lambda r: r.means[:, 1]),
        Attribute("z", "world units", lambda r: r.means[:, 2]),
        Attribute("distance", "world units from the origin",
                  lambda r: np.sqrt((r.means * r.means).sum(axis=1))),
        Attribute("opacity", "0-1 (0 for a zero quaternion)", lambda r: r.opacity),
        Attribute("opacity_logit", "raw stored logit",
                  lambda r: r.scene.opacity_logits[r.rows].astype(np.float64)),
        Attribute("scale_0", "world units (std. dev.)", lambda r: r.scales[:, 0]),
        Attribute("scale_1", "world units (std. dev.)", lambda r: r.scales[:, 1]),
        Attribute("scale_2", "world units (std. dev.)", lambda r: r.scales[:, 2], surfels=False),
        Attribute("max_scale", "world units (largest std. dev.)", lambda r: r.scales.max(axis=1)),
        Attribute("min_scale", "world units (smallest std. dev.)", lambda r: r.scales.min(axis=1)),
        Attribute("anisotropy", "ratio largest / smallest scale (>= 1)",
                  lambda r: np.exp(r.log_scales.max(axis=1) - r.log_scales.min(axis=1))),
        Attribute("r", "0-1 (DC colour, 0.5 + SH_C0 f_dc_0)", lambda r: 0.5 + SH_C0 * r.sh[:, 0, 0]),
        Attribute("g", "0-1 (DC colour, 0.5 + SH_C0 f_dc_1)", lambda r: 0.5 + SH_C0 * r.sh[:, 0, 1]),
        Attribute("b", "0-1 (DC colour, 0.5 + SH_C0 f_dc_2)", lambda r: 0.5 + SH_C0 * r.sh[:, 0, 2]),
        Attribute("sh_degree", "highest SH band with a nonzero coefficient (0-3)",
                  _effective_sh_degree),
    ]
    return {a.name: a for a in table}


#: Every attribute by name, in the order help texts and statistics list them.
ATTRIBUTES: dict[str, Attribute] = _attributes()


def names_for(scene: Scene) -> list[str]:
    """The attribute names that exist for ``scene``'s kind."""
    from ..scene.splats import SplatKind

    surfel = scene.kind is SplatKind.SURFEL_2D
    return [name for name, a in ATTRIBUTES.items() if a.surfels or not surfel]


def help_table() -> str:
    """``name  unit`` lines for help texts."""
    return "\n".join(f"  {a.name:<14} {a.unit}" for a in ATTRIBUTES.values())
