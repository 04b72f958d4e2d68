"""splatgl's NumPy reference against gsplat's fisheye and pinhole projection (issue 26).

gsplat and torch are NOT project dependencies: this script runs its gsplat side in a separate
virtual environment, outside the repository, made once::

    python3 -m venv /work/gsplat-venv
    /work/gsplat-venv/bin/pip install numpy torch
    BUILD_NO_CUDA=1 /work/gsplat-venv/bin/pip install --no-build-isolation gsplat==1.5.3

and is run with the project's own Python (splatgl importable)::

    python benchmarks/gsplat_fisheye.py --gsplat-python /work/gsplat-venv/bin/python \\
        [--size 480] [--distances 1,0.3] [SCENE ...]

The gsplat side (this file with ``--worker``, in gsplat's environment, on the CPU) projects with
gsplat's own PyTorch twin of its CUDA projection, ``gsplat.cuda._torch_impl.
_fully_fused_projection`` (``camera_model`` "fisheye" or "pinhole": view z for the near test
and the sort key), then rasterizes with :func:`composite`, a NumPy port of gsplat's
``RasterizeToPixels3DGSFwd.cu``: tiles from ``_isect_tiles``' ``floor``/``ceil`` bounds, a
stable sort by the float32 key per tile, pixel centres ``j + 0.5``, ``alpha = min(0.999,
o exp(-sigma))``, skip ``sigma < 0`` or ``alpha < 1/255``, stop where ``T (1 - alpha) <=
1e-4``, ``C + T bg``.  (gsplat's own torch rasterizer calls CUDA kernels and nerfacc, so it
cannot run without a GPU.)  Colours are splatgl's SH colours of the splats (the shared scenes
are SH degree 0), both sides get the same K (``Camera.fisheye``: ``f = 0.5 min(W, H) /
theta_d(fov / 2)``, principal point ``(W/2, H/2)``), pose and black background.

Prints, per scene, view distance and camera: PSNR (pixels off by more than 1/255) of the
reference under INRIA and under ``--convention gsplat`` against gsplat; for the fisheye, the
gsplat-convention reference with each of splatgl's own lens rules put back (distance sort key,
distance + angle cull, both = the behaviour before issue 26) and with the principal point
moved by half a pixel (the size of a sub-pixel convention error); how far the projected means
(px) and conics (relative) of both sides differ; and how far each per-splat sort key is from a
per-pixel order (each splat's depth of greatest contribution along the pixel's own ray, with
the same 2D footprints), which neither renderer does.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

TILE = 16
SCENES = ["ply/donut_sh0.ply", "compressed_ply/guitar.compressed.ply",
          "compressed_ply/biker.compressed.ply"]


def composite(means2d, conics, colors, opacities, lists, key, width, height, background):
    """gsplat's per-tile blend (float32) of the splats in ``lists`` ((tiles,) arrays of ids),
    in the order of ``key(ids, px, py)``: (M,) per-splat keys or (M, P) per-pixel keys.

    Returns (H, W, 4) float32 RGBA (colour composited over ``background``)."""
    f32 = np.float32
    tiles_x = (width + TILE - 1) // TILE
    out = np.zeros((height, width, 4), f32)
    jj, ii = np.meshgrid(np.arange(TILE), np.arange(TILE))
    bg = np.asarray(background, f32)
    for t, ids in enumerate(lists):
        y0, x0 = (t // tiles_x) * TILE, (t % tiles_x) * TILE
        px = (x0 + jj.ravel()).astype(f32) + f32(0.5)
        py = (y0 + ii.ravel()).astype(f32) + f32(0.5)
        T = np.ones(px.size, f32)
        C = np.zeros((px.size, 3), f32)
        if ids.size:
            k = key(ids, px, py)
            g = (ids[np.argsort(k, kind="stable")][:, None] + np.zeros((1, px.size), int)
                 if k.ndim == 1 else ids[np.argsort(k, 0, kind="stable")])
            dx, dy = means2d[g, 0] - px, means2d[g, 1] - py
            co = conics[g]
            sigma = f32(0.5) * (co[..., 0] * dx * dx + co[..., 2] * dy * dy) + co[..., 1] * dx * dy
            a = np.minimum(f32(0.999), opacities[g] * np.exp(-sigma))
            a = np.where((sigma < 0) | (a < f32(1.0 / 255.0)), f32(0.0), a).astype(f32)
            after = np.cumprod(f32(1.0) - a, 0, dtype=f32)            # T after each entry
            before = np.concatenate([np.ones((1, px.size), f32), after[:-1]], 0)
            stop = (a > 0) & (after <= f32(1e-4))
            first = np.where(stop.any(0), stop.argmax(0), len(g))     # not blended, exclusive
            live = np.arange(len(g))[:, None] < first
            C = (np.where(live, a * before, f32(0.0))[..., None] * colors[g]).sum(0)
            T = np.where(first < len(g), before[np.minimum(first, len(g) - 1),
                                                np.arange(px.size)], after[-1])
        h, w = min(TILE, height - y0), min(TILE, width - x0)
        rgba = np.concatenate([C + T[:, None] * bg, (1 - T)[:, None]], 1)
        out[y0:y0 + h, x0:x0 + w] = rgba.reshape(TILE, TILE, 4)[:h, :w]
    return out


def tile_lists(lo, hi, keep, width, height):
    """(tiles,) arrays of splat ids whose tile rectangle ``[lo, hi)`` (N, 2) holds each tile."""
    tiles_x, tiles_y = (width + TILE - 1) // TILE, (height + TILE - 1) // TILE
    ids = np.flatnonzero(keep)
    lists = []
    for ty in range(tiles_y):
        row = ids[(lo[ids, 1] <= ty) & (hi[ids, 1] > ty)]
        for tx in range(tiles_x):
            lists.append(row[(lo[row, 0] <= tx) & (hi[row, 0] > tx)])
    return lists


def worker(src: str, dst: str) -> None:
    """gsplat side: gsplat's torch projection, then :func:`composite` with its tile bounds."""
    import torch
    from gsplat.cuda._torch_impl import _fully_fused_projection, _quat_scale_to_covar_preci

    d = np.load(src)
    w, h = int(d["width"]), int(d["height"])
    f = lambda name: torch.tensor(d[name], dtype=torch.float32)  # noqa: E731
    covars, _ = _quat_scale_to_covar_preci(f("quats"), f("scales"), compute_preci=False,
                                           triu=False)
    radii, means2d, depths, conics, _ = _fully_fused_projection(
        f("means"), covars, f("viewmat")[None], f("K")[None], w, h, eps2d=0.3,
        near_plane=float(d["near"]), camera_model=str(d["model"]))
    radii, means2d, depths, conics = (v[0].numpy() for v in (radii, means2d, depths, conics))
    lo = np.floor(means2d / TILE - radii / TILE).astype(np.int64)    # _isect_tiles' bounds
    hi = np.ceil(means2d / TILE + radii / TILE).astype(np.int64)
    lists = tile_lists(lo, hi, (radii > 0).all(1), w, h)
    rgba = composite(means2d, conics, d["colors"].astype(np.float32),
                     d["opacities"].astype(np.float32), lists,
                     lambda ids, px, py: depths[ids], w, h, d["background"])
    np.savez(dst, rgba=rgba, means2d=means2d, conics=conics, visible=(radii > 0).all(1))


def gsplat_render(python, scene, camera, near, background, tmp):
    """(RGBA, projection arrays) of gsplat's side for ``camera`` (through ``python``)."""
    from splatgl.splatmath import project as pm

    means, view = pm.anchored(scene.means, scene.anchor, camera, np.float64)
    colors = pm.sh_color(scene.sh.astype(np.float32), pm.view_dirs(means.astype(np.float32),
                                                                   view))
    k = np.array([[camera.fx, 0, camera.cx], [0, camera.fy, camera.cy], [0, 0, 1]])
    src, dst = Path(tmp) / "in.npz", Path(tmp) / "out.npz"
    np.savez(src, means=means, quats=scene.rotations, scales=scene.scales,
             opacities=scene.opacities, colors=colors, viewmat=view.world_to_camera, K=k,
             width=camera.width, height=camera.height, near=near,
             model="fisheye" if camera.is_lens else "pinhole", background=background)
    subprocess.run([python, __file__, "--worker", str(src), str(dst)], check=True)
    with np.load(dst) as out:
        return dict(out)


def reference(scene, camera, settings, compat, lens_rules=False, depth=None):
    """Reference RGBA; ``lens_rules``: splatgl's distance key and cull even under GSPLAT;
    ``depth``: replace the sort key of the visible rows by ``depth(p_cam)``."""
    from splatgl.splatmath import project as pm
    from splatgl.reference import stages
    from splatgl.reference.binning import emit_keys, sort, tile_ranges
    from splatgl.reference.options import ReferenceOptions
    from splatgl.reference.rasterize import rasterize

    options = ReferenceOptions(compat)
    saved = stages.gsplat_fisheye
    if lens_rules:
        stages.gsplat_fisheye = lambda camera, options: False
    try:
        proj = stages.project(scene, camera, settings, np.float32, options)
    finally:
        stages.gsplat_fisheye = saved
    if depth is not None:
        means, view = pm.anchored(scene.means, scene.anchor, camera, np.float32)
        key = depth(pm.to_camera(means, view)).astype(np.float32)
        proj = dataclasses.replace(proj, depth=np.where(proj.visible, key, 0).astype(np.float32))
    keys, values = sort(*emit_keys(proj))
    r = rasterize(proj, values, tile_ranges(keys, proj.n_tiles), settings.background, options)
    return np.concatenate([r.color, r.alpha[..., None]], -1).astype(np.float32), proj


def per_pixel_orders(scene, camera, settings):
    """{"distance", "view z", "per pixel"}: the GSPLAT reference's footprints blended in each
    order (:func:`composite`); per pixel: ``t* = d^T P mu / d^T P d`` (the depth of greatest
    contribution along the pixel's unit ray d, P the camera-space precision)."""
    from splatgl.splatmath import project as pm
    from splatgl.scene.quaternion import quat_to_rotmat
    from splatgl.reference import stages
    from splatgl.reference.options import ReferenceOptions

    proj = stages.project(scene, camera, settings, np.float32, ReferenceOptions("gsplat"))
    means, view = pm.anchored(scene.means, scene.anchor, camera, np.float64)
    p = pm.to_camera(means, view)
    m = view.rotation[None] @ quat_to_rotmat(scene.rotations.astype(np.float64))
    prec = (m * np.maximum(scene.scales, 1e-7)[:, None, :] ** -2) @ np.swapaxes(m, 1, 2)
    prec_mu = np.einsum("nij,nj->ni", prec, p)

    def ray_depth(ids, px, py):
        u, v = (px - camera.cx) / camera.fx, (py - camera.cy) / camera.fy
        theta = np.hypot(u, v)
        s = np.sin(theta) / np.where(theta > 0, theta, 1.0)
        d = np.stack([u * s, v * s, np.cos(theta)], -1)
        return prec_mu[ids] @ d.T / np.einsum("pi,nij,pj->np", d, prec[ids], d)

    lists = tile_lists(proj.rect_min, proj.rect_max, proj.visible, camera.width, camera.height)
    args = (proj.mean2d, proj.conic, proj.color, proj.opacity, lists)
    dist, z = np.linalg.norm(p, axis=1).astype(np.float32), p[:, 2].astype(np.float32)
    size = (camera.width, camera.height, settings.background)
    return {"distance": composite(*args, lambda ids, px, py: dist[ids], *size),
            "view z": composite(*args, lambda ids, px, py: z[ids], *size),
            "per pixel": composite(*args, ray_depth, *size)}


def compare_view(python, scene, cam, settings, near, per_pixel: bool) -> None:
    """Print one camera's lines (see the module docstring)."""
    from splatgl.measure.evaluation.metrics import image_errors, psnr

    def fmt(a, b):
        off = round(image_errors(a, b).off_1 * a.shape[0] * a.shape[1])
        return "%6.1f dB (%6d px)" % (psnr(a[..., :3], b[..., :3]), off)

    with tempfile.TemporaryDirectory() as tmp:
        g = gsplat_render(python, scene, cam, near, settings.background, tmp)
    gs = g["rgba"]
    inria = reference(scene, cam, settings, "inria")[0]
    ref_gs, proj = reference(scene, cam, settings, "gsplat")
    both = proj.visible & g["visible"]
    dm = np.abs(proj.mean2d - g["means2d"])[both].max()
    dc = (np.abs(proj.conic - g["conics"])[both]
          / np.abs(proj.conic[both]).max(1, keepdims=True)).max()
    print(f"  {cam.projection.value}: inria {fmt(inria, gs)}, gsplat convention "
          f"{fmt(ref_gs, gs)}; |mean2d| <= {dm:.1e} px, conic <= {dc:.1e} rel")
    if not cam.is_lens:
        return
    shifted = dataclasses.replace(cam, cx=cam.cx + 0.5, cy=cam.cy + 0.5)
    ref = lambda camera, **kw: reference(scene, camera, settings, "gsplat", **kw)  # noqa: E731
    rows = {
        "splatgl's key and cull (before issue 26)": ref(cam, lens_rules=True),
        "splatgl's key (distance)": ref(cam, depth=lambda p: np.linalg.norm(p, axis=1)),
        "splatgl's cull (distance, angle)": ref(cam, lens_rules=True, depth=lambda p: p[:, 2]),
        "principal point + 0.5 px": ref(shifted),
    }
    for what, (img, _) in rows.items():
        print(f"    gsplat convention with {what}: {fmt(img, gs)}")
    if per_pixel:
        orders = per_pixel_orders(scene, cam, settings)
        print(f"    against a per-pixel order: distance key "
              f"{fmt(orders['distance'], orders['per pixel'])}, view z "
              f"{fmt(orders['view z'], orders['per pixel'])}")


def main() -> None:
    from splatgl import Camera, RenderSettings, default_camera, load_scene
    from splatgl.scene.settings import resolve_near

    repo = Path(__file__).resolve().parents[1]
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scenes", nargs="*", help="paths under --scenes-dir (default: three real ones)")
    ap.add_argument("--scenes-dir", default=os.environ.get(
        "SPLATGL_SHARED_SCENES", str(repo.parent / "shared" / "scenes")))
    ap.add_argument("--gsplat-python", required=True, help="Python of the torch+gsplat venv")
    ap.add_argument("--size", type=int, default=480)
    ap.add_argument("--fov", type=float, default=180.0)
    ap.add_argument("--distances", default="1,0.3", help="default_camera distance scales")
    ap.add_argument("--no-per-pixel", action="store_true", help="skip the per-pixel order")
    args = ap.parse_args()
    settings = RenderSettings(background=(0.0, 0.0, 0.0))
    for name in args.scenes or SCENES:
        scene = load_scene(Path(args.scenes_dir) / name)
        near = resolve_near(settings, scene.robust_radius)
        for dist in (float(v) for v in args.distances.split(",")):
            pinhole = default_camera(scene, args.size, args.size, distance_scale=dist)
            fisheye = Camera.fisheye(args.size, args.size, args.fov, pinhole.world_to_camera)
            print(f"{name}, distance scale {dist}:")
            for cam in (pinhole, fisheye):
                compare_view(args.gsplat_python, scene, cam, settings, near,
                             not args.no_per_pixel)


if __name__ == "__main__":
    if sys.argv[1:2] == ["--worker"]:
        worker(*sys.argv[2:4])
    else:
        main()
