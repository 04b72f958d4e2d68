"""Scene conversion between file formats, and the error a round trip through a format introduces.

:func:`convert` reads any supported format, optionally caps the SH degree, writes the format the
output's extension names (atomically, via :func:`splatgl.formats.save_scene`), reads the output
back and measures it against the input with :func:`conversion_error`.
"""

from __future__ import annotations

import inspect
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..constants import SH_C0
from ..errors import SplatglError, add_note
from ..writing.outputs import check_output_path
from . import detect_format, load_scene, save_scene, stored_bytes, writer_for
from .spz_axes import Axes, check_choice as check_spz_axes
from ..scene.splats import Scene

#: Highest SH degree each writable format stores (formats not listed store degree 3).
MAX_SH_DEGREE_OF_FORMAT = {"splat": 0}
#: The attributes :func:`conversion_error` measures and writers bound.
ATTRIBUTES = ("position", "scale", "opacity", "rotation", "color", "sh_rest")
#: Formats whose writers write, and readers read back (``allow_empty``), a scene of zero splats;
#: the others' files need bounds, chunks or textures of at least one splat.
EMPTY_FORMATS = ("ply", "spz")
#: Formats that store a scene's other per-splat properties (:attr:`Scene.extras`).
EXTRAS_FORMATS = ("ply",)


def extra_properties(scene: Scene) -> tuple[str, ...]:
    """The names of ``scene``'s other per-splat properties that hold something: normals that
    are all zero (the INRIA files' placeholders, which the PLY writer writes anyway) do not."""
    extras = scene.extras
    if extras is None:
        return ()
    normals = [n for n in ("nx", "ny", "nz") if n in extras.dtype.names]
    blank = not any(np.any(extras[n] != 0) for n in normals)
    return tuple(n for n in extras.dtype.names if not (blank and n in normals))


def dropped_note(names, format_name: str | None = None, why: str | None = None) -> str | None:
    """The one line saying which per-splat properties were not written, or None for none."""
    if not names:
        return None
    why = why or f"the {format_name} format cannot hold them; .ply keeps them"
    return f"per-splat properties dropped: {', '.join(names)} ({why})"


def error_bounds(writer, scene: Scene, **options) -> dict | None:
    """The writer's per-attribute bounds for ``scene`` (None for lossless writers)."""
    fn = getattr(writer, "error_bounds", None)
    if fn is None:
        return None
    accepted = inspect.signature(fn).parameters
    return fn(scene, **{k: v for k, v in options.items() if k in accepted})


def within_bounds(error: dict, bounds: dict | None) -> dict[str, bool] | None:
    """Per attribute: is the measured max error inside its bound (attributes with a bound)."""
    if bounds is None:
        return None
    return {name: bool(error[name]["max"] <= bounds[name]) for name in ATTRIBUTES
            if bounds.get(name) is not None and error.get(name) is not None}


def _stats(values: np.ndarray) -> dict[str, float]:
    values = np.asarray(values, np.float64).ravel()
    if values.size == 0:
        return {"max": 0.0, "mean": 0.0}
    return {"max": float(values.max()), "mean": float(values.mean())}


def rotation_angle_deg(qa: np.ndarray, qb: np.ndarray) -> np.ndarray:
    """(N,) float64 angle in degrees of the rotation taking ``qa`` to ``qb`` ((N, 4) w-first).

    Quaternions are normalised first; ``q`` and ``-q`` are the same rotation (angle 0).  Uses
    ``4 atan2(|a - s b|, |a + s b|)`` with ``s = sign(a . b)``: for unit vectors that atan2 is
    half the 4D angle between them, and a rotation turns by twice that angle.  Accurate near 0
    (unlike ``2 acos(|a . b|)``).
    """
    a = np.asarray(qa, np.float64)
    b = np.asarray(qb, np.float64)
    a = a / np.linalg.norm(a, axis=1, keepdims=True)
    b = b / np.linalg.norm(b, axis=1, keepdims=True)
    s = np.where((a * b).sum(axis=1) < 0.0, -1.0, 1.0)[:, None]
    quarter = np.arctan2(np.linalg.norm(a - s * b, axis=1), np.linalg.norm(a + s * b, axis=1))
    return np.degrees(4.0 * quarter)


def conversion_error(a: Scene, b: Scene) -> dict:
    """Per-attribute error of scene ``b`` (e.g. read back from a written file) against ``a``.

    Both scenes must hold the same splats in the same order (same count and kind).  Each entry
    is ``{"max": float, "mean": float}`` over all splats (and components):

    - ``position``: Euclidean distance of the means, world units.
    - ``scale``: relative error of each activated scale, ``|exp(lb - la) - 1|`` (unitless).
    - ``opacity``: absolute error of the activated opacity (sigmoid of the logit), in [0, 1].
    - ``rotation``: angle between the rotations in degrees (``q`` and ``-q`` count as equal).
    - ``color``: SH DC colour error ``SH_C0 |f_dc_b - f_dc_a|`` per channel, in 0-1 colour units
      (the view-independent part of the colour; 1/255 is one 8-bit step).
    - ``sh_rest``: absolute error of the SH coefficients of degree >= 1 both scenes hold, or
      None when either has degree 0.

    Also ``count``, ``sh_degree`` ``[a, b]``, ``bit_exact`` (every stored value identical,
    the other per-splat properties of ``a`` too, same SH degree and kind), ``dropped``: the
    other per-splat properties of ``a`` that ``b`` lacks (:func:`extra_properties`), and
    ``color_outside_01``: how many DC colour channels of ``a``
    (``0.5 + SH_C0 f_dc``) lie outside [0, 1], which 8-bit formats clip (their error is the
    distance clipped, not a quantisation step).
    """
    if a.count != b.count:
        raise SplatglError(f"cannot compare scenes of {a.count} and {b.count} splats")
    if a.kind is not b.kind:
        raise SplatglError(f"cannot compare a {a.kind.value} scene with a {b.kind.value} scene")
    f64 = np.float64
    position = np.linalg.norm(b.means.astype(f64) - a.means.astype(f64), axis=1)
    with np.errstate(over="ignore"):  # a log-scale clipped by hundreds: an error of inf
        scale = np.abs(np.expm1(b.log_scales.astype(f64) - a.log_scales.astype(f64)))
        oa = 1.0 / (1.0 + np.exp(-a.opacity_logits.astype(f64)))
        ob = 1.0 / (1.0 + np.exp(-b.opacity_logits.astype(f64)))
    color = SH_C0 * np.abs(b.sh[:, 0].astype(f64) - a.sh[:, 0].astype(f64))
    k = min(a.sh.shape[1], b.sh.shape[1])
    rest = None
    if k > 1:
        rest = _stats(np.abs(b.sh[:, 1:k].astype(f64) - a.sh[:, 1:k].astype(f64)))
    kept = b.extras.dtype.names if b.extras is not None else ()
    dropped = [n for n in extra_properties(a) if n not in kept]
    bit_exact = a.sh.shape == b.sh.shape and all(
        np.array_equal(getattr(a, n), getattr(b, n))
        for n in ("means", "quats", "log_scales", "opacity_logits", "sh")) and all(
        n in kept and a.extras[n].tobytes() == b.extras[n].astype(a.extras[n].dtype).tobytes()
        for n in (a.extras.dtype.names if a.extras is not None else ()))
    return {
        "count": a.count,
        "sh_degree": [a.sh_degree, b.sh_degree],
        "bit_exact": bool(bit_exact),
        "dropped": dropped,
        "position": _stats(position),
        "scale": _stats(scale),
        "opacity": _stats(np.abs(ob - oa)),
        "rotation": _stats(rotation_angle_deg(a.quats, b.quats)),
        "color": _stats(color),
        "sh_rest": rest,
        "color_outside_01": int(np.count_nonzero(np.abs(0.5 + SH_C0 * a.sh[:, 0].astype(f64)
                                                        - 0.5) > 0.5)),
    }


@dataclass(frozen=True)
class Conversion:
    """What :func:`convert` did: formats, sizes, SH degrees, timings and the round-trip error."""

    source: Path
    output: Path
    source_format: str
    output_format: str
    count: int
    sh_degree_in: int
    sh_degree_out: int
    output_bytes: int
    seconds: float
    error: dict
    #: For SPZ files: how the input / output's axes were decided, else None.
    input_axes: Axes | None = None
    output_axes: Axes | None = None

    def as_dict(self) -> dict:
        """JSON-ready dictionary (paths as strings)."""
        return {
            "input": str(self.source), "output": str(self.output),
            "input_format": self.source_format, "output_format": self.output_format,
            "splats": self.count, "sh_degree_in": self.sh_degree_in,
            "sh_degree_out": self.sh_degree_out, "output_bytes": self.output_bytes,
            "seconds": self.seconds, "error": self.error,
            "input_spz_axes": self.input_axes and self.input_axes.as_dict(),
            "output_spz_axes": self.output_axes and self.output_axes.as_dict(),
        }


def convert(source: str | Path, output: str | Path, *, drop_invalid: bool = False,
            sh_degree: int | None = None, force: bool = False, progress=None,
            spz_axes: str | None = None, **writer_options) -> Conversion:
    """Convert the scene file ``source`` to ``output`` (format from its extension).

    ``sh_degree`` caps the SH degree written (never pads).  A format that stores fewer SH bands
    than the scene has (.splat: degree 0) drops the rest with a :class:`UserWarning`.  Refuses to
    replace an existing ``output`` unless ``force``; the file appears only when complete.
    ``progress`` is passed to :func:`load_scene` for both reads.  ``writer_options`` go to the
    writer (``version=2`` for SPZ).  ``spz_axes`` ("rub"/"rdf", see
    :mod:`splatgl.formats.spz_axes`) applies to each SPZ side: the axes assumed for an input
    that records none, and the axes the output is written in.  For lossy writers the error
    dictionary also holds ``bounds`` (per attribute, what the format's quantisation allows for
    this scene; None where no a-priori bound exists) and ``within_bounds``.  Writers that reorder the splats (SOG,
    compressed PLY) are compared row by row in the order written.

    Raises :class:`SplatglError` for a missing or malformed input, an output format that cannot
    be written, an existing output without ``force`` or a write that fails.
    """
    source, output = Path(source), Path(output)
    writer = writer_for(output)  # unsupported extension: fail before reading anything
    # IN itself, a missing or read-only folder, an existing OUT without force: before reading
    check_output_path(output, overwrite=force, inputs={"IN": source})
    if sh_degree is not None and not 0 <= sh_degree <= 3:
        raise SplatglError(f"--sh-degree must be 0-3, got {sh_degree}")
    t0 = time.perf_counter()
    spz_axes = check_spz_axes(spz_axes)
    source_format = detect_format(source).NAME
    axes_in = spz_axes if source_format == "spz" else None
    axes_out = spz_axes if writer.NAME == "spz" else None
    if spz_axes is not None and axes_in is axes_out is None:
        raise SplatglError(f"{source} -> {output}: --spz-axes applies to .spz files only")
    if axes_out is not None:
        writer_options["axes"] = axes_out
    scene = load_scene(source, drop_invalid=drop_invalid, progress=progress, spz_axes=axes_in,
                       allow_empty=True)
    if scene.count == 0 and writer.NAME not in EMPTY_FORMATS:
        raise SplatglError(f"{output}: {source} holds no splats, and the {writer.NAME} format "
                           "cannot hold zero splats; nothing written (write .ply or .spz)")
    degree = scene.sh_degree if sh_degree is None else min(sh_degree, scene.sh_degree)
    limit = MAX_SH_DEGREE_OF_FORMAT.get(writer.NAME, 3)
    if degree > limit:
        warnings.warn(f"{output}: the {writer.NAME} format stores SH degree {limit} only; "
                      f"dropping SH degrees {limit + 1}..{degree} of the input", stacklevel=2)
        degree = limit
    written = scene if degree == scene.sh_degree else scene.with_sh_degree(degree)
    try:
        order = save_scene(output, written, **writer_options)
    except OSError as exc:
        raise SplatglError(f"{output}: cannot write: {exc.strerror or exc}") from None
    try:   # OUT is whole from here: a Ctrl-C cuts short only the report
        bounds = error_bounds(writer, written, **writer_options)
        del written
        back = load_scene(output, progress=progress, spz_axes=axes_out, allow_empty=True)
        if order is not None:
            scene = scene.subset(order)
        error = conversion_error(scene, back)
    except KeyboardInterrupt as exc:
        raise add_note(exc, written_note(output))
    error["bounds"] = bounds
    error["within_bounds"] = within_bounds(error, bounds)
    size = stored_bytes(output)
    return Conversion(source, output, source_format, writer.NAME, scene.count, scene.sh_degree,
                      back.sh_degree, size, time.perf_counter() - t0, error,
                      _axes(source, source_format, axes_in), _axes(output, writer.NAME, axes_out))


def written_note(output: Path) -> str:
    """What a conversion stopped while it measured its round trip says: OUT is complete."""
    return (f"{output} was written whole; only its round-trip report was cut short (read it "
            "with 'splatgl info', or convert again with --force for the report)")


def _axes(path: Path, format_name: str, axes: str | None) -> Axes | None:
    if format_name != "spz":
        return None
    from .spz import read_axes
    with warnings.catch_warnings():  # a conflict with the file was reported on loading
        warnings.simplefilter("ignore")
        return read_axes(path, axes)
