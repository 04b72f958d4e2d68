"""``splatgl conformance export DIR``: write the kit (:mod:`splatgl.measure.conformance.cases`).

Layout::

    DIR/index.json                 kit version, conventions, and per case: files, size, camera
                                   model, near plane, background, tolerance, tags
    DIR/README.md                  the conventions a renderer must follow (below)
    DIR/cases/NAME/scene.ply       the scene, INRIA PLY (float32, raw log-scales and logits)
    DIR/cases/NAME/camera.json     splatgl's single-camera JSON (world_to_camera, OpenCV axes)
    DIR/cases/NAME/reference.exr   float32 R, G, B, A, Z: C + (1 - A) bg, A, and D / A
    DIR/cases/NAME/reference.png   8-bit RGB of the same

The folder is written under a temporary name beside DIR and renamed when complete, so an
interrupted export leaves nothing behind; ``--force`` replaces only an older kit or a file, and
only then (:mod:`splatgl.measure.conformance.kit_folder`).
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np

from ...constants import ALPHA_MAX, ALPHA_MIN, LOW_PASS, T_MIN, TILE_SIZE
from ...errors import SplatglError
from ...formats import save_scene
from ...cameras.camera_files import save_camera
from ...writing.atomic import atomic_write_text, temp_path, write_error
from ...imagefiles.images import write_image
from ...reference import render_reference
from .cases import Case
from .index import GENERATOR, PLAIN_NAME, PLAIN_NAME_RULE
from .kit_folder import check_export_target, replace_with

#: Version of the kit's layout and rules (index.json "version").
KIT_VERSION = 1

CONVENTIONS = {
    "pixel_centres": "pixel (i, j) (row i from the top, column j) has its centre at (j + 0.5, i + 0.5)",
    "y_direction": "row 0 of every image is the top; camera axes are OpenCV's (+x right, +y down, +z forward)",
    "sh_layout": "f_dc_0..2 then f_rest_* channel-major (all R coefficients, then G, then B); the "
                 "degree follows from the count (0, 9, 24, 45); colour = max(sum h Y(d) + 0.5, 0), "
                 "d = normalize(mean - camera centre), no upper clamp",
    "activation": "scale = exp(scale_*), opacity = sigmoid(opacity), rotation = normalize(rot_0..3) "
                  "as (w, x, y, z); a quaternion of norm below 1e-12 is not drawn",
    "projection": f"EWA with the 3DGS Jacobian clamp (1.3 tan(half fov)), +{LOW_PASS} px^2 low pass; "
                  "fisheye (equidistant, OpenCV k1..k4) and equirectangular cameras linearise their "
                  "own projection at each centre and sort by distance",
    "alpha": f"alpha = min({ALPHA_MAX}, o exp(-q / 2)), skipped below {ALPHA_MIN:.6f} (1/255)",
    "early_stop": f"front to back; stop without adding a splat once T (1 - alpha) < {T_MIN:g}",
    "order": f"splats sorted by view z (distance for fisheye and panorama); the reference bins "
             f"them into {TILE_SIZE}x{TILE_SIZE} tiles within ceil(3 sqrt(lambda_max)) pixels",
    "background": "images are C + (1 - A) background, the background given per case",
    "near": "splats whose view z is at or below the case's near plane are not drawn",
}


def _readme(cases: list[Case]) -> str:
    lines = ["# splatgl conformance kit", "",
             "Render every case with your renderer and score the images with",
             "`splatgl conformance score DIR --images YOURS/` (one image per case, named",
             "`NAME.png`, `.exr`, `.webp`, `.jpg` or `.tif`, the size of its camera).", "",
             "## Conventions", ""]
    lines += [f"- **{k.replace('_', ' ')}**: {v}" for k, v in CONVENTIONS.items()]
    lines += ["", "## Cases", "", "| case | what | size | camera | min PSNR | max share > 4/255 |",
              "|---|---|---|---|---:|---:|"]
    lines += [f"| {c.name} | {c.what} | {c.camera.width}x{c.camera.height} | {c.camera.model.name} "
              f"| {c.min_psnr:g} | {c.max_off_4:g} |" for c in cases]
    lines += ["", "The camera JSON holds `width`, `height`, `fx`, `fy`, `cx`, `cy` (pixels; orthographic: "
              "pixels per world unit; fisheye: pixels per radian and `distortion`), `world_to_camera` "
              "(4x4 row-major) and `projection`.", ""]
    return "\n".join(lines)


def case_entry(case: Case) -> dict:
    cam = case.camera
    return {"name": case.name, "what": case.what, "scene": f"cases/{case.name}/scene.ply",
            "camera": f"cases/{case.name}/camera.json",
            "reference_exr": f"cases/{case.name}/reference.exr",
            "reference_png": f"cases/{case.name}/reference.png",
            "width": cam.width, "height": cam.height, "projection": cam.model.name,
            "splats": case.scene.count, "kind": case.scene.kind.value,
            "sh_degree": case.scene.sh_degree, "near": case.settings.near,
            "background": list(case.settings.background),
            "tolerance": {"min_psnr": case.min_psnr, "max_off_4": case.max_off_4},
            "tags": list(case.tags)}


def _named_for_user(exc: BaseException, tmp: Path, out: Path) -> BaseException:
    """``exc`` naming the user's ``out`` where it named the temporary folder ``tmp`` (a failed
    write: one line, :func:`~splatgl.writing.atomic.write_error`)."""
    if isinstance(exc, OSError):
        name = str(exc.filename or "")
        return write_error(out / os.path.relpath(name, tmp) if name.startswith(str(tmp)) else out, exc)
    if isinstance(exc, SplatglError) and str(tmp) in str(exc):
        exc.args = (str(exc).replace(str(tmp), str(out)),)
        if str(getattr(exc, "path", "")).startswith(str(tmp)):
            exc.path = str(exc.path).replace(str(tmp), str(out))
    return exc


def _write_kit(tmp: Path, cases: list[Case], progress) -> dict:
    entries = []
    for k, case in enumerate(cases):
        folder = tmp / "cases" / case.name
        folder.mkdir(parents=True)
        save_scene(folder / "scene.ply", case.scene)
        save_camera(folder / "camera.json", case.camera)
        ref = render_reference(case.scene, case.camera, case.settings, np.float32)
        rgba = ref.rgba
        a = ref.alpha
        z = np.where(a >= 1e-3, ref.depth / np.where(a >= 1e-3, a, 1.0), 0.0).astype(np.float32)
        write_image(folder / "reference.exr", rgba, depth=z)
        write_image(folder / "reference.png", rgba)
        entries.append(case_entry(case))
        if progress is not None:
            progress(k + 1, len(cases), "conformance: reference images")
    index = {"version": KIT_VERSION, "generator": GENERATOR, "conventions": CONVENTIONS,
             "cases": entries}
    atomic_write_text(tmp / "index.json", json.dumps(index, indent=1) + "\n")
    atomic_write_text(tmp / "README.md", _readme(cases))
    return index


def export_kit(out: str | Path, cases: list[Case], force: bool = False, progress=None) -> dict:
    """Write the kit into ``out`` (module doc); returns the index.  ``out`` must not exist
    unless ``force``, and then only a kit or a file is replaced, once the new kit is complete
    (:mod:`splatgl.measure.conformance.kit_folder`)."""
    out = Path(out)
    check_export_target(out, force)
    for case in cases:
        if not PLAIN_NAME.fullmatch(case.name):
            raise SplatglError(f"case {case.name!r}: not a plain name ({PLAIN_NAME_RULE})")
    tmp = Path(os.path.abspath(temp_path(out)))
    try:
        tmp.mkdir()
        index = _write_kit(tmp, cases, progress)
        replace_with(tmp, out, force)
    except BaseException as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        named = _named_for_user(exc, tmp, out)
        if named is not exc:
            raise named from None
        raise
    return index
