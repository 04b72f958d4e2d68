"""How far the first-order splat approximation of a distorted camera is from a per-pixel
ray-traced one (docs/camera-models.md, "Lens distortion").

EWA splatting linearises the projection at each splat's centre, so under lens distortion every
splat is drawn as the ellipse of the distortion's Jacobian at its centre.  :func:`raytrace` is
the per-pixel twin that makes no such approximation: each pixel centre is undistorted to its
own ray (Newton, :func:`splatgl.cameras.opencv.undistort`), and each splat contributes its 3D
Gaussian's largest value along that ray,
``alpha = o exp(-(mu^T S mu - (d^T S mu)^2 / d^T S d) / 2)`` (``S`` the inverse camera-space
covariance, ``d`` the ray, ``mu`` the centre; the peak at ``t = d^T S mu / d^T S d``, at
``t = 0`` if behind), with the quad path's order (view z of the centres, ties by index),
colours (SH towards the centre) and blending rules (alpha cap 0.99, skip below 1/255, stop at
T < 1e-4).  The splat path's 0.3 px^2 low-pass dilation is folded into each splat's 3D
covariance, ``S^-1 + 0.3 J^T (J J^T)^-2 J`` with J the model's Jacobian at the centre (so that
``J (.) J^T`` adds exactly 0.3 I there); without it (``--no-dilation``) sub-pixel splats, which
the dilation widens, dominate the difference.  The pinhole column is the baseline: what the
linearisation costs without distortion.

    python benchmarks/distortion_accuracy.py [SCENE ...] [--size 128x96]

prints PSNR (RGB) of the NumPy reference against the ray-traced twin for a pinhole and for
mild and strong distortion on the same poses (about a minute per scene at 128x96).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

from splatgl.api import default_camera, render_reference_rgba
from splatgl.cameras.camera import Camera
from splatgl.cameras.opencv import OpenCV, undistort
from splatgl.cameras.view import View
from splatgl.constants import ALPHA_MAX, ALPHA_MIN, T_MIN
from splatgl.measure.evaluation.metrics import psnr
from splatgl.formats import load_scene
from splatgl.scene.quaternion import quat_to_rotmat
from splatgl.scene.splats import Scene
from splatgl.scene.settings import RenderSettings
from splatgl.constants import LOW_PASS
from splatgl.splatmath.project import covariance_3d, jacobian, sh_color, to_camera, view_dirs

#: The distortions measured: (label, model).  Mild: a typical phone or DSLR calibration;
#: strong: action-camera barrel and a strong pincushion.
DISTORTIONS = [
    ("pinhole", None),
    ("mild barrel k1 -0.05 k2 0.01", OpenCV(k1=-0.05, k2=0.01)),
    ("strong barrel k1 -0.3 k2 0.08 p1 0.003", OpenCV(k1=-0.3, k2=0.08, p1=0.003)),
    ("strong pincushion k1 0.3 k2 0.1", OpenCV(k1=0.3, k2=0.1)),
]


def pixel_rays(camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """``(rays (H*W, 3) float64 (a, b, 1), ok (H*W,))`` through the pixel centres, row-major;
    ``ok`` False where a distorted pixel has no undistorted ray (beyond the fold)."""
    v, u = np.mgrid[0:camera.height, 0:camera.width] + 0.5
    d = np.stack([(u.ravel() - camera.cx) / camera.fx, (v.ravel() - camera.cy) / camera.fy], -1)
    if isinstance(camera.model, OpenCV):
        n, ok = undistort(d, camera.model)
    else:
        n, ok = d, np.ones(len(d), bool)
    return np.concatenate([n, np.ones((len(n), 1))], -1), ok


def raytrace(scene: Scene, camera: Camera, settings: RenderSettings = RenderSettings(),
             dilate: bool = True, block: int = 256) -> np.ndarray:
    """(H, W, 4) float64 RGBA of ``scene`` through ``camera`` (pinhole or OpenCV), per pixel
    (see the module doc; ``dilate``: the low pass folded into the 3D covariances); colour
    composited over ``settings.background``, alpha ``1 - T``."""
    view = View.of(camera, settings, scene)
    cam = view.anchored
    means = scene.relative_means.astype(np.float64)
    p_cam = to_camera(means, cam)
    # every splat the model draws (no screen cull: the pinhole's peak-alpha bound is the splat
    # path's own, and this twin must not inherit it)
    keep = cam.model.visible(p_cam, cam, view.near) & (scene.opacities >= ALPHA_MIN)
    idx = np.flatnonzero(keep)
    idx = idx[np.lexsort((idx, p_cam[idx, 2].astype(np.float32)))]   # the quad path's order
    w = cam.rotation
    cov = w @ covariance_3d(quat_to_rotmat(scene.rotations[idx].astype(np.float64)),
                            scene.scales[idx].astype(np.float64)) @ w.T
    mu = p_cam[idx]
    if dilate:   # + LOW_PASS J^T (J J^T)^-2 J: J (.) J^T = LOW_PASS I at the centre
        j = jacobian(mu, cam)
        jj_inv = np.linalg.inv(j @ np.swapaxes(j, 1, 2))
        cov = cov + LOW_PASS * np.swapaxes(j, 1, 2) @ jj_inv @ jj_inv @ j
    inv = np.linalg.inv(cov)
    s_mu = np.einsum("kij,kj->ki", inv, mu)
    mu_s_mu = np.einsum("ki,ki->k", mu, s_mu)
    color = sh_color(scene.sh[idx].astype(np.float64), view_dirs(means[idx], cam), settings.sh_degree)
    opac = scene.opacities[idx].astype(np.float64)
    rays, ok = pixel_rays(cam)
    t = np.where(ok, 1.0, 0.0)        # pixels without a ray see only the background
    done = ~ok
    rgb = np.zeros((len(rays), 3))
    for start in range(0, len(idx), block):
        sl = slice(start, start + block)
        d_s_mu = rays @ s_mu[sl].T                                         # (P, K)
        d_s_d = np.einsum("pi,kij,pj->pk", rays, inv[sl], rays, optimize=True)
        peak = np.where(d_s_mu > 0, d_s_mu * d_s_mu / d_s_d, 0.0)         # t* >= 0 only
        alpha = np.minimum(ALPHA_MAX, opac[sl] * np.exp(-0.5 * np.maximum(mu_s_mu[sl] - peak, 0.0)))
        alpha = np.where((alpha < ALPHA_MIN) | done[:, None], 0.0, alpha)
        seq = np.concatenate([t[:, None], 1.0 - alpha], 1).cumprod(axis=1)
        kept = seq[:, 1:] >= T_MIN                                         # a prefix per pixel
        rgb += (np.where(kept, alpha, 0.0) * seq[:, :-1]) @ color[sl]
        n = kept.sum(axis=1)
        t = seq[np.arange(len(t)), n]
        done |= n < alpha.shape[1]
    bg = np.asarray(settings.background, np.float64)
    out = np.concatenate([rgb + t[:, None] * bg, 1.0 - t[:, None]], -1)
    return out.reshape(camera.height, camera.width, 4)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scenes", nargs="*", default=["ply/donut_sh0.ply", "compressed_ply/guitar.compressed.ply"],
                   help="scene files, relative to $SPLATGL_SHARED_SCENES (default ../shared/scenes)")
    p.add_argument("--size", default="128x96", help="image size WxH (default 128x96)")
    p.add_argument("--distances", default="1.0,0.3", help="default_camera distance scales")
    p.add_argument("--no-dilation", action="store_true",
                   help="leave the low-pass dilation out of the ray-traced twin")
    args = p.parse_args(argv)
    width, height = (int(v) for v in args.size.split("x"))
    root = Path(os.environ.get("SPLATGL_SHARED_SCENES", Path(__file__).resolve().parents[1].parent / "shared" / "scenes"))
    settings = RenderSettings()
    print(f"| scene | distance | {' | '.join(label for label, _ in DISTORTIONS)} |")
    print("|---|---:|" + "---:|" * len(DISTORTIONS))
    for name in args.scenes:
        scene = load_scene(root / name if not Path(name).is_file() else Path(name))
        for dist in (float(v) for v in args.distances.split(",")):
            base = default_camera(scene, width, height, distance_scale=dist)
            # a 90-degree horizontal field of view, where distortion shows
            base = Camera(width, height, width / 2, width / 2, width / 2, height / 2, base.world_to_camera)
            row = []
            for _, model in DISTORTIONS:
                cam = base if model is None else base.with_model(model)
                row.append(psnr(render_reference_rgba(scene, cam, settings)[..., :3],
                                raytrace(scene, cam, settings, not args.no_dilation)[..., :3]))
            print(f"| {Path(name).stem} | {dist:g} | " + " | ".join(f"{v:.1f}" for v in row) + " |",
                  flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
