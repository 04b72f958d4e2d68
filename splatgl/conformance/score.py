"""``splatgl conformance score DIR --images THEIRS/`` and ``conformance render``: score another
renderer's images of the kit's cases (:mod:`splatgl.conformance.export`), and render them with
splatgl's own renderers.

Each case's image (``THEIRS/NAME.png``, ``.exr``, ``.webp``, ``.jpg`` or ``.tif``) is read and
checked as ``compare --image`` reads one (:mod:`splatgl.evaluation.their_image`: size, y
direction, mirror, alpha convention, background) and scored against the case's reference EXR.
A case passes at its tolerance (``min_psnr``, ``max_off_4``).  For a failing case the knob that
best explains it is found by re-rendering the reference with each approximation real viewers
make (:mod:`splatgl.evaluation.explain`); a failed check (an image upside down, of another
size) is its own explanation.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ..cameras.files import load_camera
from ..errors import SplatglError
from ..evaluation.explain import candidates, explain
from ..evaluation.metrics import image_errors
from ..evaluation.their_image import match_to_reference, read_their_image
from ..formats import load_scene
from ..model.settings import RenderSettings
from ..output.images import read_image
from ..reference import render_reference

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


def load_index(kit: str | Path) -> dict:
    kit = Path(kit)
    path = kit / "index.json"
    if not path.is_file():
        raise SplatglError(f"{kit}: not a conformance kit (no index.json; splatgl conformance "
                           "export writes one)")
    try:
        index = json.loads(path.read_text())
        cases = index["cases"]
        if not isinstance(cases, list):
            raise TypeError
    except (ValueError, KeyError, TypeError):
        raise SplatglError(f"{path}: not a conformance index (field 'cases' missing or not a list)") from None
    return index


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


def score_case(kit: Path, images: Path, entry: dict, explain_failures: bool = True) -> CaseScore:
    name = entry["name"]
    path = find_image(images, name)
    if path is None:
        return CaseScore(name, "missing", explanation=f"no {name}.png/.exr/... in {images}")
    ref = read_image(kit / entry["reference_exr"])
    ref_rgb, ref_alpha = ref[..., :3], ref[..., 3]
    try:
        img = read_their_image(path, entry["width"], entry["height"])
        matched = match_to_reference(img, ref_rgb, ref_alpha, tuple(entry["background"]))
    except SplatglError as exc:
        why = str(exc).split(": ", 1)[-1]          # the check that failed, without the file name
        return CaseScore(name, "fail", explanation=why.split("; pass --")[0])
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


def render_kit(kit: str | Path, out: str | Path, kind: str = "quad", suffix: str = ".exr",
               progress=None) -> list[str]:
    """Render every case with splatgl's ``kind`` renderer into ``out/NAME<suffix>``; returns
    the cases skipped, with why (a renderer that cannot draw a case's camera or splats)."""
    from ..api import Renderer
    from ..output.images import write_image

    kit, out = Path(kit), Path(out)
    index = load_index(kit)
    out.mkdir(parents=True, exist_ok=True)
    skipped = []
    with Renderer() as renderer:
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
