"""The golden set: hashes of float images over every shared scene, camera model and renderer.

A refactoring that must change no pixel is checked by recording the set before it and checking
it after:

    python benchmarks/golden.py record golden.json      # before
    python benchmarks/golden.py check golden.json       # after: lists every case that changed

Each case runs ``splatgl render ... -o case.exr`` through the command line's own entry point (in
this process, so the scene loads and programs compile once per scene), reads the EXR back and
hashes its float32 colour+alpha and its depth separately.  A case the command refuses records
its one-line message instead, so refusals are part of the behaviour too.  Images are small
(160x96; panoramas 192x96) so the NumPy reference stays affordable: about 10 minutes here.

Scenes: every file in ``$SPLATGL_SHARED_SCENES`` (else ``../shared/scenes``) that the table
below names and that exists, the bundled demo, and a seeded synthetic 2DGS surfel scene.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import io
import json
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

SHARED = ("ply/donut_sh0.ply", "compressed_ply/biker.compressed.ply",
          "compressed_ply/guitar.compressed.ply", "spz/biker_v4.spz", "spz/donut_sh0_v2.spz",
          "fixtures/test64_sh3.compressed.ply", "fixtures/minimal.splat",
          "fixtures/minimal.ksplat", "fixtures/minimal-v2.spz", "fixtures/minimal-v3.spz",
          "fixtures/minimal-v4.spz", "fixtures/minimal-raw.spz")

CAMERAS = {
    "default": [],
    "close": ["--distance", "0.3"],
    "turned": ["--transform", '{"rotate_deg": [20, 75, -10]}', "--distance", "1.3"],
}
MODELS = {
    "perspective": ["--width", "160", "--height", "96"],
    "orthographic": ["--width", "160", "--height", "96", "--orthographic"],
    "fisheye": ["--width", "160", "--height", "96", "--projection", "fisheye"],
    "equirect": ["--width", "192", "--height", "96", "--projection", "equirectangular"],
}
RENDERERS = ("quad", "tile", "reference")

#: Settings variants of the quad path (and a few of the others), on two scenes.
VARIANTS = {
    "sort-bucket16": ["--sort", "bucket16"],
    "sort-gpu": ["--sort", "gpu"],
    "extent-square": ["--extent", "square"],
    "extent-fast": ["--extent", "fast"],
    "antialias": ["--antialias"],
    "storage-compact": ["--gpu-storage", "compact"],
    "storage-half-sh": ["--gpu-storage", "half-sh"],
    "early-stop-on": ["--early-stop", "on"],
    "early-stop-off": ["--early-stop", "off"],
    "precision-16f": ["--precision", "rgba16f"],
    "preprocess-vertex": ["--preprocess", "vertex"],
    "preprocess-compute": ["--preprocess", "compute"],
    "sh-degree-1": ["--sh-degree", "1"],
    "background": ["--background", "0.2,0.4,0.9"],
    "near": ["--near", "0.05"],
    "fov-70-close": ["--fov", "70", "--distance", "0.3"],
    "stereo": ["--stereo", "0.05"],
    "stereo-top-bottom": ["--stereo", "0.05", "--stereo-layout", "top-bottom"],
    "tile-gsplat": ["--renderer", "tile", "--convention", "gsplat"],
    "reference-gsplat": ["--renderer", "reference", "--convention", "gsplat"],
    "reference-antialias": ["--renderer", "reference", "--antialias"],
    "tile-antialias": ["--renderer", "tile", "--antialias"],
    "scale-transform": ["--transform", '{"translate": [0.1, -0.2, 0.3], "scale": 1.7}'],
}


def shared_dir() -> Path:
    env = os.environ.get("SPLATGL_SHARED_SCENES")
    return Path(env) if env else Path.cwd().parent / "shared" / "scenes"


def surfel_scene(path: Path) -> Path:
    """A seeded 2DGS scene of 600 surfels on a wavy sheet, written as a PLY."""
    from splatgl import Scene, SplatKind, save_scene

    rng = np.random.default_rng(7)
    n = 600
    xy = rng.uniform(-1, 1, (n, 2))
    means = np.column_stack([xy, 0.2 * np.sin(3 * xy[:, 0]) + 3.0])
    quats = rng.normal(size=(n, 4))
    scales = rng.uniform(0.03, 0.12, (n, 2))
    opac = rng.uniform(0.3, 0.95, n)
    sh = rng.normal(scale=0.4, size=(n, 4, 3))
    save_scene(path, Scene.from_activated(means, quats, scales, opac, sh, SplatKind.SURFEL_2D))
    return path


def scenes(work: Path) -> dict[str, str]:
    from splatgl.commands._common import demo_scene_path

    found = {"demo": str(demo_scene_path()), "surfels": str(surfel_scene(work / "surfels.ply"))}
    root = shared_dir()
    for name in SHARED:
        if (root / name).is_file():
            found[name] = str(root / name)
    return found


def read_exr(path: Path) -> tuple[np.ndarray, np.ndarray | None]:
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    try:
        spec = inp.spec()
        pixels = inp.read_image(0, 0, 0, spec.nchannels, "float")
    finally:
        inp.close()
    names = list(spec.channelnames)
    rgba = np.ascontiguousarray(pixels[..., [names.index(c) for c in "RGBA"]], np.float32)
    depth = pixels[..., names.index("Z")] if "Z" in names else None
    return rgba, None if depth is None else np.ascontiguousarray(depth, np.float32)


def digest(a: np.ndarray | None) -> str | None:
    return None if a is None else hashlib.sha256(a.tobytes()).hexdigest()[:16]


def run_case(argv: list[str], out: Path) -> dict:
    from splatgl.cli import main

    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = main(["render", *argv, "-o", str(out)])
    if code != 0:
        lines = err.getvalue().strip().splitlines()
        return {"refused": lines[-1] if lines else f"exit {code}"}
    rgba, depth = read_exr(out)
    out.unlink()
    return {"colour": digest(rgba), "depth": digest(depth), "shape": list(rgba.shape)}


def cases(found: dict[str, str]):
    for scene_name, path in found.items():
        for cam, cam_args in CAMERAS.items():
            for model, model_args in MODELS.items():
                for renderer in RENDERERS:
                    yield (f"{scene_name}|{cam}|{model}|{renderer}",
                           [path, *cam_args, *model_args, "--renderer", renderer])
    for scene_name in ("ply/donut_sh0.ply", "compressed_ply/guitar.compressed.ply", "demo"):
        if scene_name not in found:
            continue
        for variant, args in VARIANTS.items():
            extra = [] if "--renderer" in args else ["--renderer", "quad"]
            yield (f"{scene_name}|variant|{variant}",
                   [found[scene_name], "--width", "160", "--height", "96", *extra, *args])


def lod_cases(found: dict[str, str], work: Path):
    """LOD cuts of the donut: built once, rendered by threshold and by budget."""
    from splatgl.cli import main

    if "ply/donut_sh0.ply" not in found:
        return
    lod = work / "donut.lod.ply"
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        if main(["lod", found["ply/donut_sh0.ply"], "-o", str(lod)]) != 0:
            return
    for name, args in {"lod-threshold-1": ["--lod-threshold", "1"],
                       "lod-threshold-4-far": ["--lod-threshold", "4", "--distance", "3"],
                       "lod-budget-5000": ["--lod-budget", "5000"],
                       "lod-blend-1": ["--lod-threshold", "2", "--lod-blend", "1", "--distance", "2"]}.items():
        yield f"donut.lod|{name}", [str(lod), "--width", "160", "--height", "96", *args]


def record(work: Path, only: str | None = None) -> dict[str, dict]:
    found = scenes(work)
    results = {}
    todo = list(cases(found)) + list(lod_cases(found, work))
    for n, (name, argv) in enumerate(todo, 1):
        if only and only not in name:
            continue
        results[name] = run_case(argv, work / "case.exr")
        print(f"[{n}/{len(todo)}] {name}: {results[name].get('colour') or results[name].get('refused')}",
              file=sys.stderr, flush=True)
    return results


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("action", choices=("record", "check"))
    p.add_argument("file", type=Path, help="the golden JSON to write (record) or compare with (check)")
    p.add_argument("--only", default=None, help="only cases whose name contains this text")
    args = p.parse_args()
    with tempfile.TemporaryDirectory(prefix="splatgl-golden-") as tmp:
        results = record(Path(tmp), args.only)
    if args.action == "record":
        args.file.write_text(json.dumps(results, indent=1, sort_keys=True) + "\n")
        print(f"recorded {len(results)} cases in {args.file}")
        return 0
    golden = json.loads(args.file.read_text())
    changed = [k for k in results if golden.get(k) != results[k]]
    missing = [k for k in golden if k not in results and not args.only]
    reworded = [k for k in changed if "refused" in results[k] and "refused" in golden.get(k, {})]
    for k in changed:
        tag = "REWORDED" if k in reworded else "CHANGED"
        print(f"{tag} {k}: {golden.get(k)} -> {results[k]}")
    for k in missing:
        print(f"MISSING {k}")
    print(f"{len(results) - len(changed)} of {len(results)} cases unchanged; "
          f"{len(changed) - len(reworded)} changed, {len(reworded)} refusals reworded, "
          f"{len(missing)} missing")
    return 1 if len(changed) > len(reworded) or missing else 0


if __name__ == "__main__":
    sys.exit(main())
