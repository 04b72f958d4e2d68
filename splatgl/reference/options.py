"""Options of the NumPy reference rasterizer: which published convention it follows.

The default is the 3DGS rasterizer of Kerbl et al. 2023 (DESIGN.md section 2).  ``GSPLAT`` follows
gsplat's conventions instead, so that the reference can be matched against that tool:

* extent: per-axis and opacity-aware, ``r_x = ceil(min(3.33, sqrt(2 ln(o / (1/255)))) sqrt(cov_xx))``
  (likewise y), tiles ``[floor((u - r_x) / 16), ceil((u + r_x) / 16))``; splats with
  ``o < 1/255`` or entirely off screen are culled;
* alpha clamp 0.999 (selectable through :attr:`ReferenceOptions.alpha_max`);
* early stop when ``T (1 - alpha) <= 1e-4`` (3DGS: ``< 1e-4``);
* a fisheye is near-culled and sorted by view z, as gsplat's EWA fisheye does (splatgl's own
  rule is the distance; :func:`splatgl.reference.stages.gsplat_fisheye`).

Everything else (projection, low pass, SH colour, key layout, pixel centres at ``j + 0.5``) is
shared.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..constants import ALPHA_MAX, GSPLAT_ALPHA_MAX
from ..scene.emulation import Emulation
from ..scene.settings import Convention, Order


#: Which published rasterizer's conventions the reference follows: the settings' enum, so
#: ``RenderSettings.convention`` and the reference's options are one type.
Compat = Convention


@dataclass(frozen=True)
class ReferenceOptions:
    """How the reference rasterizes.

    Attributes:
        compat: the convention followed (see the module docstring).
        alpha_max: upper clamp of each splat's alpha; ``None`` takes the emulation's
            ``alpha_max`` knob if set, else the convention's own (0.99 for INRIA, 0.999 for GSPLAT).
        emulation: the approximations of other viewers followed (:mod:`splatgl.scene.emulation`;
            applied by :mod:`splatgl.reference.emulation`).
        order: global (3DGS) or per pixel (:mod:`splatgl.reference.per_pixel`).
        window: with the per-pixel order, None sorts each pixel's list exactly; an integer is
            the tile renderer's bounded re-sort (its twin: each pixel holds back that many
            splats, :func:`splatgl.reference.per_pixel.window_order`).
    """

    compat: Compat = Compat.INRIA
    alpha_max: float | None = None
    emulation: Emulation = Emulation()
    order: Order = Order.GLOBAL
    window: int | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "compat", Compat(self.compat))
        object.__setattr__(self, "order", Order(self.order))
        if self.window is not None and int(self.window) < 1:
            raise ValueError(f"window must be at least 1, got {self.window}")
        if self.alpha_max is not None and not 0.0 < float(self.alpha_max) <= 1.0:
            raise ValueError(f"alpha_max must be in (0, 1], got {self.alpha_max}")

    @property
    def resolved_alpha_max(self) -> float:
        """The alpha clamp in effect."""
        if self.alpha_max is not None:
            return float(self.alpha_max)
        if self.emulation.alpha_max is not None:
            return float(self.emulation.alpha_max)
        return GSPLAT_ALPHA_MAX if self.compat is Compat.GSPLAT else ALPHA_MAX

    @property
    def alpha_min(self) -> float:
        """Fragments with a smaller alpha are skipped (1/255 unless emulated)."""
        return float(self.emulation.min_alpha)

    @property
    def stop_inclusive(self) -> bool:
        """True when blending stops at ``T (1 - alpha) <= T_MIN`` (gsplat), False for ``<``."""
        return self.compat is Compat.GSPLAT


def as_options(compat: "Compat | ReferenceOptions | str") -> ReferenceOptions:
    """A :class:`ReferenceOptions` from a Compat value (or its name) or an options object."""
    if isinstance(compat, ReferenceOptions):
        return compat
    return ReferenceOptions(Compat(compat))
