"""The edit operations from their command-line texts (``splatgl edit``'s option values), so the
CLI and a Python caller holding the same strings get the same operations and the same errors."""

from __future__ import annotations

from ..errors import SplatglError
from ..scene.json_text import loads_strict
from ..scene.transform import transform_from_object
from .decimate import Decimate
from .floaters import RemoveFloaters
from .operations import CropBox, CropSphere, DropInvalid, Filter, ShDegree

#: Keys of ``--remove-floaters KEY=VALUE,...`` and the RemoveFloaters field each sets.
FLOATER_KEYS = {"neighbours": "neighbours", "k": "neighbours", "sigma": "sigma",
                "opacity": "opacity"}


def _numbers(text: str, n: int, option: str, form: str) -> list[float]:
    parts = [p.strip() for p in str(text).split(",")]
    try:
        values = [float(p) for p in parts]
    except ValueError:
        raise SplatglError(f"{option} {text!r}: expected {form} (numbers)") from None
    if len(values) != n:
        raise SplatglError(f"{option} {text!r}: expected {form} ({n} numbers, got {len(values)})")
    return values


def crop_box(text: str) -> CropBox:
    """``X0,Y0,Z0,X1,Y1,Z1`` (min and max corners), or a JSON object ``{"min": [..], "max":
    [..]}`` with the keys of ``--transform`` (``rotate_deg`` or ``rotation``, ``translate``,
    ``scale``) placing the box: a rotated box."""
    t = str(text).strip()
    if t.startswith("{"):
        obj = loads_strict(t, "--crop-box")
        if not isinstance(obj, dict) or "min" not in obj or "max" not in obj:
            raise SplatglError("--crop-box: a JSON box needs \"min\" and \"max\" (3 numbers each)")
        placement = {k: v for k, v in obj.items() if k not in ("min", "max")}
        transform = transform_from_object(placement, "--crop-box") if placement else None
        for key in ("min", "max"):
            if not isinstance(obj[key], list):
                raise SplatglError(f"--crop-box: \"{key}\" must be a list of 3 numbers, got "
                                   f"{obj[key]!r}")
        return CropBox(tuple(obj["min"]), tuple(obj["max"]), transform)
    v = _numbers(t, 6, "--crop-box", "X0,Y0,Z0,X1,Y1,Z1")
    return CropBox(tuple(v[:3]), tuple(v[3:]))


def crop_sphere(text: str) -> CropSphere:
    """``X,Y,Z,R``: centre and radius."""
    v = _numbers(text, 4, "--crop-sphere", "X,Y,Z,R")
    return CropSphere(tuple(v[:3]), v[3])


def remove_floaters(text: str | None = None) -> RemoveFloaters:
    """Empty for the defaults, or ``KEY=VALUE,...`` with keys neighbours (or k), sigma, opacity."""
    values: dict = {}
    for part in filter(None, (p.strip() for p in (text or "").split(","))):
        key, sep, value = part.partition("=")
        field = FLOATER_KEYS.get(key.strip())
        if not sep or field is None:
            raise SplatglError(f"--remove-floaters {text!r}: expected KEY=VALUE pairs with keys "
                               f"neighbours, sigma, opacity (e.g. neighbours=16,sigma=3)")
        try:
            number = float(value)
            # a count stays an integer, so a refusal shows it as given (neighbours=0: "got 0")
            values[field] = int(number) if field == "neighbours" and number.is_integer() else number
        except ValueError:
            raise SplatglError(f"--remove-floaters: {key.strip()}={value!r} is not a number") \
                from None
    return RemoveFloaters(**values)


def sh_degree(text) -> ShDegree:
    try:
        return ShDegree(int(str(text).strip()))
    except ValueError:
        raise SplatglError(f"--sh-degree must be an integer 0-3, got {text!r}") from None


#: Option name (without dashes) -> builder from the option's text.
BUILDERS = {
    "crop-box": crop_box,
    "crop-sphere": crop_sphere,
    "filter": lambda text: Filter(text),
    "remove": lambda text: Filter(text, invert=True),
    "remove-floaters": remove_floaters,
    "decimate": Decimate.parse,
    "sh-degree": sh_degree,
    "drop-invalid": lambda text=None: DropInvalid(),
}


def operation(option: str, text: str | None = None):
    """The operation for ``--OPTION TEXT`` (``option`` with or without the dashes)."""
    name = option.lstrip("-")
    if name not in BUILDERS:
        raise SplatglError(f"unknown edit operation --{name} (known: "
                           f"{', '.join('--' + k for k in BUILDERS)})")
    return BUILDERS[name](text) if text is not None else BUILDERS[name]()


def inverted(op):
    """``op`` keeping the other splats (``--invert`` after a crop or filter)."""
    from dataclasses import replace

    if not hasattr(op, "invert"):
        raise SplatglError(f"--invert applies to --crop-box, --crop-sphere, --filter and "
                           f"--remove, not --{op.name}")
    return replace(op, invert=not op.invert)
