"""Score a renderer nobody here wrote with the conformance kit: gsplat 1.5.3 (nerfstudio's
library, PyPI ``gsplat``) through its pure-PyTorch path, on the CPU.

gsplat's own PyTorch code does everything up to blending, reading nothing of splatgl's: it
activates the kit's stored PLY values, builds covariances (``_quat_scale_to_covar_preci``),
projects (``_fully_fused_projection``: EWA, its Jacobian clamp, +0.3 px^2, a per-axis
opacity-aware extent), evaluates SH (``_spherical_harmonics``), bins and sorts (``_isect_tiles``:
64-bit (tile, depth) keys and ``torch.sort``; ``_isect_offset_encode``).  Its torch blending
(``_rasterize_to_pixels``) calls a CUDA kernel and nerfacc, so the blending is the NumPy port of
gsplat's ``RasterizeToPixels3DGSFwd.cu`` in benchmarks/gsplat_fisheye.py (``composite``: alpha =
min(0.999, o exp(-sigma)), skipped below 1/255, stop where T (1 - alpha) <= 1e-4), fed gsplat's
own sorted tile lists.  Other candidates tried on this machine (docs/fidelity.md): PlayCanvas
splat-transform's WebGPU image output (no adapter: Dawn rejects Mesa's lavapipe), gausscam
(WGSL; needs 35 storage buffers per shader stage, lavapipe has 32), splatstream/vkgs
(segfaults at import without a GPU), gswarp (CUDA streams only).

gsplat and torch are NOT project dependencies: the gsplat side runs in its own virtual
environment (made as benchmarks/gsplat_fisheye.py says) and this script with the project's
Python (splatgl importable)::

    python benchmarks/external_renderer.py --gsplat-python /work/gsplat-venv/bin/python [--kit DIR]

It exports a conformance kit (or reads ``--kit``), renders every case gsplat's path draws
(perspective and orthographic 3DGS), writes its float RGBA as EXR and runs ``splatgl
conformance score``: pass/fail per case with the knob that best explains each failure.  For the
real scenes it also prints ``compare --explain``'s ranking.  The result is in docs/fidelity.md.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

TILE = 16


def worker(jobs_path: str) -> None:
    """Runs in gsplat's environment: each job drawn by gsplat's torch code (module doc) and the
    rasterizer port; saves (H, W, 4) float32 RGBA as .npy."""
    import torch
    from gsplat.cuda._torch_impl import (_fully_fused_projection, _isect_offset_encode,
                                         _isect_tiles, _quat_scale_to_covar_preci,
                                         _spherical_harmonics)
    sys.path.insert(0, str(Path(__file__).parent))
    from gsplat_fisheye import composite

    for job in json.loads(Path(jobs_path).read_text()):
        d = np.load(job["scene"])
        w, h = job["width"], job["height"]
        t = lambda a: torch.tensor(np.asarray(a), dtype=torch.float32)  # noqa: E731
        means = t(d["means"])
        quats = torch.nn.functional.normalize(t(d["quats"]), dim=-1)
        covars, _ = _quat_scale_to_covar_preci(quats, torch.exp(t(d["log_scales"])),
                                               compute_preci=False, triu=False)
        opac = torch.sigmoid(t(d["logits"]))
        radii, means2d, depths, conics, _ = _fully_fused_projection(
            means, covars, t(job["viewmat"])[None], t(job["K"])[None], w, h, eps2d=0.3,
            near_plane=job["near"], camera_model=job["model"])
        centre = torch.linalg.inv(t(job["viewmat"]))[:3, 3]
        coeffs = t(d["sh"])
        degree = int(round(coeffs.shape[1] ** 0.5)) - 1
        colors = torch.clamp_min(_spherical_harmonics(degree, means - centre, coeffs) + 0.5, 0.0)
        tw, th = (w + TILE - 1) // TILE, (h + TILE - 1) // TILE
        _, isect_ids, flatten_ids = _isect_tiles(means2d, radii, depths, TILE, tw, th)
        offsets = _isect_offset_encode(isect_ids, 1, tw, th)[0].reshape(-1).numpy()
        ends = np.append(offsets[1:], len(flatten_ids))
        flat = flatten_ids.numpy() % means.shape[0]
        lists = [flat[a:b] for a, b in zip(offsets, ends)]             # in gsplat's order
        rgba = composite(means2d[0].numpy(), conics[0].numpy(), colors.numpy(), opac.numpy(),
                         lists, lambda ids, px, py: np.arange(len(ids)), w, h,
                         np.asarray(job["background"], np.float32))
        np.save(job["out"], rgba)


def job_for(entry: dict, kit: Path, out: Path):
    """The gsplat job of a kit case, or None (with why) where its path cannot draw it."""
    from splatgl.cameras.camera_files import load_camera
    from splatgl.formats import load_scene

    if entry["projection"] not in ("perspective", "orthographic") or entry["kind"] != "3dgs":
        return None, f"{entry['projection']} {entry['kind']}"
    cam = load_camera(kit / entry["camera"])
    scene = load_scene(kit / entry["scene"])                # raw values, as stored in the PLY
    arrays = out / f"{entry['name']}.scene.npz"
    np.savez(arrays, means=scene.means, quats=scene.quats, log_scales=scene.log_scales,
             logits=scene.opacity_logits, sh=scene.sh)
    k = [[cam.fx, 0, cam.cx], [0, cam.fy, cam.cy], [0, 0, 1]]
    return {"scene": str(arrays), "width": cam.width, "height": cam.height, "K": k,
            "viewmat": np.asarray(cam.world_to_camera).tolist(), "near": entry["near"],
            "model": "ortho" if entry["projection"] == "orthographic" else "pinhole",
            "background": entry["background"], "out": str(out / f"{entry['name']}.npy")}, ""


def main() -> None:
    if len(sys.argv) > 2 and sys.argv[1] == "--worker":
        worker(sys.argv[2])
        return
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--gsplat-python", required=True, help="python of gsplat's environment")
    ap.add_argument("--kit", type=Path, default=None, help="an exported kit (default: export one)")
    ap.add_argument("--out", type=Path, default=None, help="keep gsplat's images here")
    args = ap.parse_args()

    from splatgl.measure.bench.machine import describe, machine_info
    from splatgl.commands._common import demo_scene_path
    from splatgl.measure.conformance.cases import all_cases
    from splatgl.measure.conformance.export import export_kit
    from splatgl.measure.conformance.score import case_inputs, load_index, score_kit, table
    from splatgl.measure.evaluation.explain import candidates, explain
    from splatgl.formats import load_scene
    from splatgl.imagefiles.images import read_image, write_image
    from splatgl.reference import render_reference

    print(describe(machine_info()))
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        kit = args.kit or tmp / "kit"
        if args.kit is None:
            export_kit(kit, all_cases(load_scene(demo_scene_path())))
        out = args.out or tmp / "gsplat"
        out.mkdir(parents=True, exist_ok=True)
        jobs, skipped = [], []
        for entry in load_index(kit)["cases"]:
            job, why = job_for(entry, kit, out)
            (jobs.append(job) if job else skipped.append(f"{entry['name']} ({why})"))
        (tmp / "jobs.json").write_text(json.dumps(jobs))
        subprocess.run([args.gsplat_python, __file__, "--worker", str(tmp / "jobs.json")], check=True)
        for job in jobs:
            write_image(Path(job["out"]).with_suffix(".exr"), np.load(job["out"]))
            Path(job["out"]).unlink()
            Path(job["scene"]).unlink()
        print(f"gsplat 1.5.3 (PyTorch path, CPU) drew {len(jobs)} cases; not drawable: "
              f"{', '.join(skipped)}")
        print(table([s for s in score_kit(kit, out) if s.status != "missing"]))
        for entry in load_index(kit)["cases"]:
            if not entry["name"].startswith("real_") or not (out / f"{entry['name']}.exr").is_file():
                continue
            scene, camera, settings = case_inputs(kit, entry)
            got = read_image(out / f"{entry['name']}.exr")[..., :3]
            found = explain(lambda s: render_reference(scene, camera, s, np.float32,
                                                       compat=s.convention).color,
                            got, settings, candidates(scene, camera, settings))
            print(f"\n{entry['name']} (compare --explain):")
            print("\n".join(found.lines()))


if __name__ == "__main__":
    main()
