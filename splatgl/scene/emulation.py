"""The reference's emulation knobs: the approximations real splat viewers make, as settings.

Each knob changes one rule of the NumPy reference (:mod:`splatgl.reference`) away from the
3DGS rasterizer towards what some viewer does; :class:`Emulation` holds one value per knob, the
default being the reference itself.  ``splatgl compare --emulate KNOB=VALUE`` (repeatable),
``--explain`` (which knob brings the reference closest to an image) and the conformance kit
read them; only the reference applies them (the quad and tile renderers refuse a non-default
emulation, as they refuse ``--convention gsplat``).

========================  ==========================================================================
knob (default)            what it changes in the reference
========================  ==========================================================================
``sort`` (exact)          ``bucket16``: depth keys quantised into 65536 buckets between the nearest
                          and farthest visible splat (web viewers' counting sort; equal buckets keep
                          index order), as the quad path's ``--sort bucket16``
``extent`` (tiles)        the support of a splat on screen.  ``tiles``: the reference's whole tiles
                          inside ``ceil(3 sqrt(lambda_max))``; ``fixed``: the ellipse out to
                          sqrt(8) = 2.83 sigma (``q <= 8``); ``fixed-quad``: the square of +-2.83
                          sigma along the ellipse axes (the quad path's ``--extent fast``);
                          ``square``: the axis-aligned square ``|dx|, |dy| <= ceil(3 sqrt(lambda_max))``
                          (``--extent square``); ``opacity``: wherever ``o exp(power) >= 1/255``,
                          up to 3.33 sigma (``--extent ellipse``, the quad path's default)
``min_alpha`` (1/255)     fragments with a smaller alpha are skipped (e.g. 0.01)
``low_pass`` (0.3)        the screen-space dilation added to ``Sigma'`` (px^2; Mip-Splatting: 0.1)
``compensation`` (None)   ``on``/``off``: the antialiasing opacity factor
                          ``sqrt(det(Sigma) / det(Sigma + low_pass I))``; None follows the settings
``sh`` (None)             cap on the SH degree evaluated (0-3); None follows the settings
``half`` (off)            ``on``: positions and scales rounded to float16 (as packed viewers store them)
``alpha_max`` (None)      the alpha clamp (0.99 for the 3DGS rules; gsplat's 0.999); None: the convention's
``depth`` (auto)          what orders splats: ``z`` view-space z, ``distance`` the distance from the
                          camera; ``auto`` the camera model's (z; a fisheye or panorama: distance)
========================  ==========================================================================

The quad path's own variants map onto knobs (:func:`splatgl.reference.emulation.quad_emulation`): ``--sort bucket16`` is
``sort=bucket16``, ``--extent fast/square/ellipse`` is ``extent=fixed-quad/square/opacity``,
``--gpu-storage compact`` stores scales as float16 (closest knob ``half=on``, which also rounds
positions).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from ..constants import ALPHA_MIN, LOW_PASS, MAX_SH_DEGREE
from ..errors import SplatglError

#: ``sort`` values.
SORTS = ("exact", "bucket16")
#: ``extent`` values (see the module docstring).
EXTENTS = ("tiles", "fixed", "fixed-quad", "square", "opacity")
#: ``depth`` values.
DEPTHS = ("auto", "z", "distance")


@dataclass(frozen=True)
class Emulation:
    """One value per knob (module docstring); the defaults are the reference's own rules."""

    sort: str = "exact"
    extent: str = "tiles"
    min_alpha: float = ALPHA_MIN
    low_pass: float = LOW_PASS
    compensation: bool | None = None
    sh: int | None = None
    half: bool = False
    alpha_max: float | None = None
    depth: str = "auto"

    def __post_init__(self) -> None:
        _choice("sort", self.sort, SORTS)
        _choice("extent", self.extent, EXTENTS)
        _choice("depth", self.depth, DEPTHS)
        if not (math.isfinite(self.min_alpha) and 0.0 < self.min_alpha < 1.0):
            raise SplatglError(f"emulation min_alpha must be in (0, 1), got {self.min_alpha}")
        if not (math.isfinite(self.low_pass) and self.low_pass >= 0.0):
            raise SplatglError(f"emulation low_pass must be a finite number >= 0, got {self.low_pass}")
        if self.sh is not None and not 0 <= self.sh <= MAX_SH_DEGREE:
            raise SplatglError(f"emulation sh must be 0..{MAX_SH_DEGREE}, got {self.sh}")
        if self.alpha_max is not None and not 0.0 < self.alpha_max <= 1.0:
            raise SplatglError(f"emulation alpha_max must be in (0, 1], got {self.alpha_max}")

    @property
    def is_default(self) -> bool:
        return self == Emulation()

    def changed(self) -> dict[str, object]:
        """The knobs that differ from the reference's rules: name -> value."""
        base = Emulation()
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
                if getattr(self, f.name) != getattr(base, f.name)}

    def label(self) -> str:
        """``"sort=bucket16 extent=fixed"`` (the knobs changed, as ``--emulate`` spells them);
        ``"reference"`` for none."""
        parts = [f"{k}={format_value(v)}" for k, v in self.changed().items()]
        return " ".join(parts) or "reference"

    def with_knob(self, text: str) -> "Emulation":
        """This emulation with one more ``KNOB=VALUE`` applied (:func:`parse_knob`)."""
        name, value = parse_knob(text)
        return dataclasses.replace(self, **{name: value})


def _choice(name: str, value: str, allowed: tuple[str, ...]) -> None:
    if value not in allowed:
        raise SplatglError(f"emulation {name} must be one of {', '.join(allowed)}, got {value!r}")


def format_value(value: object) -> str:
    """A knob value as ``--emulate`` spells it (``on``/``off`` for booleans, ``%g`` numbers)."""
    if isinstance(value, bool):
        return "on" if value else "off"
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def _onoff(name: str, text: str) -> bool:
    value = {"on": True, "off": False, "true": True, "false": False, "1": True, "0": False}.get(text.lower())
    if value is None:
        raise SplatglError(f"--emulate {name}={text}: expected on or off")
    return value


def _number(name: str, text: str) -> float:
    try:
        if "/" in text:                      # 1/255
            num, den = text.split("/", 1)
            return float(num) / float(den)
        return float(text)
    except (ValueError, ZeroDivisionError):
        raise SplatglError(f"--emulate {name}={text}: expected a number") from None


def _integer(name: str, text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise SplatglError(f"--emulate {name}={text}: expected a whole number") from None


#: How each knob's value is read from ``--emulate KNOB=VALUE``.
_PARSERS = {
    "sort": lambda n, t: t,
    "extent": lambda n, t: t,
    "depth": lambda n, t: t,
    "min_alpha": _number,
    "low_pass": _number,
    "alpha_max": _number,
    "compensation": _onoff,
    "half": _onoff,
    "sh": lambda n, t: _integer(n, t),
}
#: Knob names, in the order of the module docstring.
KNOBS = tuple(f.name for f in dataclasses.fields(Emulation))


def parse_knob(text: str) -> tuple[str, object]:
    """``"KNOB=VALUE"`` -> ``(knob, value)``; a one-line error naming the knobs otherwise
    (``-`` and ``_`` are the same in knob names: ``min-alpha=0.01``)."""
    if "=" not in text:
        raise SplatglError(f"--emulate {text}: expected KNOB=VALUE with KNOB one of {', '.join(KNOBS)}")
    name, value = (part.strip() for part in text.split("=", 1))
    name = name.replace("-", "_").lower()
    if name not in _PARSERS:
        raise SplatglError(f"--emulate {text}: unknown knob {name!r}; the knobs are {', '.join(KNOBS)}")
    parsed = _PARSERS[name](name, value)
    try:
        dataclasses.replace(Emulation(), **{name: parsed})
    except SplatglError as exc:
        raise SplatglError(f"--emulate {text}: {exc}") from None
    return name, parsed


def parse_emulation(items: "list[str] | tuple[str, ...] | None") -> Emulation:
    """An :class:`Emulation` from ``KNOB=VALUE`` strings (later ones win; none: the default)."""
    emulation = Emulation()
    for item in items or ():
        emulation = emulation.with_knob(item)
    return emulation

