"""``splatgl info --stats``: per-attribute statistics (the attributes ``--filter`` sees) and the
estimated overdraw of the default view, so a user can pick filter thresholds before editing.

Overdraw: the fragments a plain quad-path draw of the default camera (:func:`default_camera`,
1280 x 720) would shade, per image pixel: each splat's opacity-aware quad (the extent where its
alpha reaches 1/255, :func:`~splatgl.splatmath.project.ellipse_axes`; for 2DGS surfels their
screen boxes) clipped to the image, summed by the coverage estimate the quad path's
``--early-stop auto`` uses (:func:`splatgl.splatmath.early_stop.coverage`).  Splats behind the
near plane count nothing.  Computed a block of rows at a time.
"""

from __future__ import annotations

import numpy as np

from ..cameras.framing import default_camera
from ..errors import CameraError
from ..scene.splats import Scene, SplatKind, activate_opacities, activate_rotations
from ..scene.settings import RenderSettings, resolve_near
from ..splatmath.early_stop import coverage
from ..splatmath.project import (covariance_2d, covariance_3d, ellipse_axes, project_means,
                                 quat_to_rotmat, to_camera)
from .attributes import ATTRIBUTES, Rows, names_for

#: Rows per block.
BLOCK = 1 << 16
#: The percentiles reported besides min, median and max.
PERCENTILES = (1.0, 99.0)


def attribute_statistics(scene: Scene) -> dict[str, dict]:
    """Per attribute (:mod:`splatgl.edit.attributes`): ``unit``, ``min``, ``p1``, ``median``,
    ``p99``, ``max``, ``mean`` over the finite values, and ``nonfinite`` (how many are not)."""
    out = {}
    for name in names_for(scene):
        if not ATTRIBUTES[name].statistic:
            continue
        values = np.empty(scene.count)
        for start in range(0, scene.count, BLOCK):
            stop = min(start + BLOCK, scene.count)
            with np.errstate(all="ignore"):  # values beyond float64 count as not finite
                values[start:stop] = ATTRIBUTES[name].compute(Rows(scene, start, stop))
        finite = values[np.isfinite(values)]
        entry = {"unit": ATTRIBUTES[name].unit, "nonfinite": int(values.size - finite.size)}
        if finite.size:
            p1, med, p99 = np.percentile(finite, [PERCENTILES[0], 50.0, PERCENTILES[1]])
            entry.update(min=float(finite.min()), p1=float(p1), median=float(med),
                         p99=float(p99), max=float(finite.max()), mean=float(finite.mean()))
        out[name] = entry
    return out


def overdraw(scene: Scene, camera=None) -> dict:
    """The default view's estimated fragments (see the module notes): ``fragments``,
    ``pixels``, ``per_pixel`` and the camera's ``width``/``height``; where no default view can
    frame the scene (positions near float32's limits), ``not_estimated`` says why instead."""
    try:
        cam = camera if camera is not None else default_camera(scene)
    except CameraError as exc:
        return {"not_estimated": str(exc)}
    near = resolve_near(RenderSettings(), scene.robust_radius)
    with np.errstate(all="ignore"):  # extreme stored values: their splats count nothing
        total = _fragments(scene, cam, near)
    pixels = cam.width * cam.height
    return {"fragments": total, "pixels": pixels, "per_pixel": total / pixels,
            "width": cam.width, "height": cam.height}


def _fragments(scene: Scene, cam, near: float) -> float:
    """The estimated fragments of every splat (those whose footprint is not finite: none)."""
    total = 0.0
    for start in range(0, scene.count, BLOCK):
        rows = slice(start, start + BLOCK)
        means = scene.means[rows].astype(np.float64)
        opac = activate_opacities(scene.opacity_logits[rows], scene.quats[rows])
        rot = activate_rotations(scene.quats[rows])
        scales = np.exp(scene.log_scales[rows].astype(np.float64))
        if scene.kind is SplatKind.SURFEL_2D:
            total += _surfel_fragments(means, rot, scales, opac, cam, near)
            continue
        p_cam = to_camera(means, cam)
        front = p_cam[:, 2] > near
        if not front.any():
            continue
        p_cam = p_cam[front]
        cov = covariance_2d(covariance_3d(quat_to_rotmat(rot[front]), scales[front]), p_cam, cam)
        axes = ellipse_axes(cov, opac[front])
        half = np.abs(axes[:, 0]) + np.abs(axes[:, 1])
        area = 4.0 * np.abs(axes[:, 0, 0] * axes[:, 1, 1] - axes[:, 0, 1] * axes[:, 1, 0])
        centre = project_means(p_cam, cam)
        ok = np.isfinite(centre).all(axis=1) & np.isfinite(half).all(axis=1) & np.isfinite(area)
        total += coverage(centre[ok] - half[ok], centre[ok] + half[ok], area[ok], cam.width,
                          cam.height)
    return total


def _surfel_fragments(means, rot, scales, opac, cam, near) -> float:
    from ..splatmath.surfel import surfel_bounds, surfel_screen

    screen = surfel_screen(means, rot, scales, cam)
    boxes = surfel_bounds(screen, opac, cam, near)
    shown = boxes.visible & (to_camera(means, cam)[:, 2] > near)
    area = 4.0 * boxes.half[:, 0] * boxes.half[:, 1]
    return float(area[shown & np.isfinite(area)].sum())


def format_statistics(stats: dict[str, dict], draw: dict | None) -> str:
    """The statistics as a text table (and the overdraw line)."""
    head = f"{'attribute':<14} {'min':>10} {'p1':>10} {'median':>10} {'p99':>10} {'max':>10}  unit"
    lines = [head]
    for name, s in stats.items():
        if "min" not in s:
            lines.append(f"{name:<14} {'(no finite values)':>54}  {s['unit']}")
            continue
        cells = " ".join(f"{s[k]:>10.4g}" for k in ("min", "p1", "median", "p99", "max"))
        bad = f" ({s['nonfinite']} not finite)" if s["nonfinite"] else ""
        lines.append(f"{name:<14} {cells}  {s['unit']}{bad}")
    if draw is not None and "not_estimated" in draw:
        lines.append(f"overdraw:      not estimated: {draw['not_estimated']}")
    elif draw is not None:
        lines.append(f"overdraw:      {draw['per_pixel']:.3g} fragments per pixel in the default "
                     f"{draw['width']}x{draw['height']} view ({draw['fragments']:.4g} fragments, "
                     "quad-path estimate)")
    return "\n".join(lines)
