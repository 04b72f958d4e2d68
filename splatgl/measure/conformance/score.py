"""``splatgl conformance score DIR --images THEIRS/`` and ``conformance render``: score another
renderer's images of the kit's cases (:mod:`splatgl.measure.conformance.export`), and render them with
splatgl's own renderers.

Each case's image (``THEIRS/NAME.png``, ``.exr``, ``.webp``, ``.jpg`` or ``.tif``) is read and
checked as ``compare --image`` reads one (:mod:`splatgl.measure.evaluation.their_image`: size, y
direction, mirror, alpha convention, background) and scored against the case's reference EXR.
A case passes at its tolerance (``min_psnr``, ``max_off_4``).  For a failing case the knob that
best explains it is found by re-rendering the reference with each approximation real viewers
make (:mod:`splatgl.measure.evaluation.explain`); a failed check (an image upside down, of another
size) is its own explanation.
"""

from __future__ import annotations

import os
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ...cameras.camera_files import load_camera
from ...errors import SplatglError
from ...writing.outputs import folder_writable
from ..evaluation.explain import candidates, explain
from ..evaluation.metrics import image_errors
from ..evaluation.their_image import match_to_reference, read_their_image
from ...formats import load_scene
from ...scene.settings import RenderSettings
from ...imagefiles.images import read_image
from ...reference import render_reference
from .index import kit_files, load_index

#: Suffixes of the images ``score`` looks for, in this order.
IMAGE_SUFFIXES = (".png", ".exr", ".webp", ".jpg", ".jpeg", ".tif", ".tiff")


@dataclass(frozen=True)
class CaseScore:
    """One case's result: ``status`` pass, fail or missing; ``psnr`` and ``off_4`` (share of
    pixels off by more than 4/255) when scored; ``explanation`` of a failure."""

    name: str
    status: str
    psnr: float | None = None
    off_4: float | None = None
    explanation: str = ""

    def as_dict(self) -> dict:
        d = asdict(self)
        if d["psnr"] == float("inf"):
            d["psnr"] = None
        return d


def case_inputs(kit: Path, entry: dict):
    """(scene, camera, settings) of an index entry."""
    scene = load_scene(kit / entry["scene"])
    camera = load_camera(kit / entry["camera"])
    return scene, camera, RenderSettings(near=entry["near"], background=tuple(entry["background"]))


def find_image(images: Path, name: str) -> Path | None:
    for suffix in IMAGE_SUFFIXES:
        path = images / f"{name}{suffix}"
        if path.is_file():
            return path
    return None


def _explain_failure(kit: Path, entry: dict, got: np.ndarray) -> str:
    scene, camera, settings = case_inputs(kit, entry)
    found = explain(lambda s: render_reference(scene, camera, s, np.float32, compat=s.convention).color,
                    got, settings, candidates(scene, camera, settings))
    if found.best is None:
        return "no knob brings the reference closer (the renderer's own difference)"
    gain = dict(found.singles)[found.best] - found.base_psnr
    return f"{found.best} (+{gain:.1f} dB)"


#: How far below the reference's lowest value (0, or a negative background) an image may go
#: (float noise) before it counts as holding negative colours.
BELOW_ZERO_TOLERANCE = 1.0 / 255.0


def _below_zero(rgb: np.ndarray, ref_rgb: np.ndarray) -> str:
    """Why an image is not scored: colours below 0 (below the reference's lowest value, with
    :data:`BELOW_ZERO_TOLERANCE`; the image's own values, under any alpha), which no renderer
    following the conventions writes (colour = max(..., 0)) and which PSNR and the share of
    pixels off would each weigh their own way; "" when there are none."""
    floor = min(0.0, float(ref_rgb.min())) - BELOW_ZERO_TOLERANCE
    low = rgb.min(axis=-1) < floor
    if not low.any():
        return ""
    return (f"colours below 0 at {low.mean() * 100:.3g}% of the pixels (down to {float(rgb.min()):.4g}); "
            "the conventions clamp colour at 0 (max(..., 0)): not scored")


def score_case(kit: Path, images: Path, entry: dict, explain_failures: bool = True) -> CaseScore:
    name = entry["name"]
    path = find_image(images, name)
    if path is None:
        return CaseScore(name, "missing", explanation=f"no {name}.png/.exr/... in {images}")
    ref_path = kit / entry["reference_exr"]
    ref = read_image(ref_path)
    if ref.shape[:2] != (entry["height"], entry["width"]) or ref.shape[2] < 4:
        raise SplatglError(f"{ref_path}: {ref.shape[1]}x{ref.shape[0]} with {ref.shape[2]} channels, "
                           f"not the case's {entry['width']}x{entry['height']} RGBA (a damaged kit)")
    ref_rgb, ref_alpha = ref[..., :3], ref[..., 3]
    try:
        img = read_their_image(path, entry["width"], entry["height"])
        matched = match_to_reference(img, ref_rgb, ref_alpha, tuple(entry["background"]))
    except SplatglError as exc:
        why = str(exc).split(": ", 1)[-1]          # the check that failed, without the file name
        return CaseScore(name, "fail", explanation=why.split("; pass --")[0])
    below = _below_zero(img.rgb, ref_rgb)
    if below:
        return CaseScore(name, "fail", explanation=below)
    errors = image_errors(matched.rgb, ref_rgb)
    tol = entry["tolerance"]
    ok = errors.psnr >= tol["min_psnr"] and errors.off_4 <= tol["max_off_4"]
    why = ""
    if not ok and explain_failures:
        why = _explain_failure(kit, entry, matched.rgb)
    return CaseScore(name, "pass" if ok else "fail", errors.psnr, errors.off_4, why)


def score_kit(kit: str | Path, images: str | Path, explain_failures: bool = True,
              progress=None) -> list[CaseScore]:
    """Every case of the kit at ``kit`` scored from ``images`` (module doc)."""
    kit, images = Path(kit), Path(images)
    if not images.is_dir():
        raise SplatglError(f"--images {images}: no such folder")
    index = load_index(kit)
    out = []
    for k, entry in enumerate(index["cases"]):
        out.append(score_case(kit, images, entry, explain_failures))
        if progress is not None:
            progress(k + 1, len(index["cases"]), "conformance: scoring cases")
    return out


def table(scores: list[CaseScore]) -> str:
    head = f"{'case':<28} {'result':<8} {'PSNR':>9} {'>4/255':>8}  explanation"
    rows = [head, "-" * len(head)]
    for s in scores:
        db = "" if s.psnr is None else ("inf" if s.psnr == float("inf") else f"{s.psnr:.2f}")
        off = "" if s.off_4 is None else f"{s.off_4 * 100:.2f}%"
        rows.append(f"{s.name:<28} {s.status.upper():<8} {db:>9} {off:>8}  {s.explanation}")
    passed = sum(s.status == "pass" for s in scores)
    rows.append(f"{passed} of {len(scores)} cases pass")
    return "\n".join(rows)


def check_render_output(kit: str | Path, out: str | Path, index: dict, suffix: str = ".exr",
                        overwrite: bool = False) -> None:
    """Refuse, before any work and in one line naming ``-o``, a folder ``out`` that
    :func:`render_kit` cannot fill: a file, the kit's own folder or one inside it, a folder
    that cannot be made or written, an image that would be one of the kit's files (through a
    link too), or an image that exists without ``overwrite``."""
    from ...writing.outputs import check_not_an_input, check_output_path, same_file

    kit, out = Path(kit), Path(out)
    if suffix not in (".exr", ".png"):
        raise SplatglError(f"--format {suffix.lstrip('.')}: must be exr or png")
    if same_file(out, kit):
        raise SplatglError(f"-o {out}: is the kit's folder {kit}; give the images a folder of their own")
    inside = os.path.realpath(out).startswith(os.path.realpath(kit).rstrip(os.sep) + os.sep)
    if inside:
        raise SplatglError(f"-o {out}: is inside the kit's folder {kit} (a kit holds only its own "
                           "files); give the images a folder of their own")
    if out.exists() and not out.is_dir():
        raise SplatglError(f"-o {out}: is a file; give a folder for the images")
    probe = Path(os.path.abspath(out))
    while not probe.exists() and probe != probe.parent:
        probe = probe.parent
    if not probe.is_dir():
        raise SplatglError(f"-o {out}: {probe} is a file, not a folder")
    if not folder_writable(probe):
        raise SplatglError(f"-o {out}: folder {probe} is not writable")
    inputs = {"the kit's file": kit_files(kit, index)}
    for entry in index["cases"]:
        target = out / f"{entry['name']}{suffix}"
        if out.is_dir():
            check_output_path(target, "-o", overwrite, inputs)
        else:
            check_not_an_input(target, "-o", inputs)


def render_kit(kit: str | Path, out: str | Path, kind: str = "quad", suffix: str = ".exr",
               progress=None, overwrite: bool = False) -> list[str]:
    """Render every case with splatgl's ``kind`` renderer into ``out/NAME<suffix>``; returns
    the cases skipped, with why (a renderer that cannot draw a case's camera or splats).
    ``out`` is checked first (:func:`check_render_output`; an existing image is replaced only
    with ``overwrite``)."""
    from ...api import Renderer
    from ...imagefiles.images import write_image

    kit, out = Path(kit), Path(out)
    index = load_index(kit)
    check_render_output(kit, out, index, suffix, overwrite)
    skipped = []
    with Renderer() as renderer:
        try:
            out.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise SplatglError(f"-o {out}: cannot make the folder ({exc.strerror})") from None
        for k, entry in enumerate(index["cases"]):
            try:
                scene, camera, settings = case_inputs(kit, entry)
                layers = renderer.render_layers(scene, camera, settings, kind)
            except SplatglError as exc:
                skipped.append(f"{entry['name']}: {exc}")
                continue
            write_image(out / f"{entry['name']}{suffix}", layers.rgba,
                        depth=layers.expected_depth() if suffix == ".exr" else None)
            if progress is not None:
                progress(k + 1, len(index["cases"]), f"conformance: rendering with {kind}")
    return skipped
