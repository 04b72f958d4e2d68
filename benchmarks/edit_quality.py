"""Pictures and tables for docs/editing.md (issue 30): decimation quality against the full
scene, and floater removal before / after.

    python benchmarks/edit_quality.py [--width 640] [--height 360]

Decimation: for each shared scene, the full scene and each decimated one are rendered from the
default camera and from the camera turned 120 and 240 degrees about it (the quad path), and the
PSNR (RGB, 0-1) of each against the full scene's image is averaged over the three views.  Three
ways to reach the same count are compared:

- ``pairs``: ``splatgl edit --decimate`` (cheapest Morton-neighbour pairs merged by moment
  matching, in rounds; :mod:`splatgl.edit.decimate`);
- ``groups``: the LOD hierarchy's fixed groups (consecutive Morton rows, ``N / target`` at a
  time, merged by the same moment matching) -- what reusing the hierarchy as it is would give;
- ``prune``: keep the ``target`` splats of largest opacity x area, merge nothing.

Floaters: the shared scenes are cleaned captures, so :func:`with_floaters` adds 300 faint blobs
between the camera and the scene; the table says how many the default ``--remove-floaters``
catches, how many real splats it takes with them, and what it takes from the clean scene.

Writes docs/results/edit-decimate-psnr.json and .md, docs/results/edit-floaters.md, and the
floater pictures docs/editing-floaters-*.png (before, after, and the removed splats alone).  Renders only, no
timings: fine to run with other work on the machine.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from splatgl.api import Renderer, default_camera  # noqa: E402
from splatgl.measure.bench.real_scenes import shared_scenes_dir  # noqa: E402
from splatgl.edit import Decimate, RemoveFloaters, apply_operations  # noqa: E402
from splatgl.measure.evaluation.metrics import psnr  # noqa: E402
from splatgl.formats import load_scene  # noqa: E402
from splatgl.lod.build import area_proxy, merge_groups  # noqa: E402
from splatgl.scene.splats import Scene  # noqa: E402
from splatgl.scene.spatial import morton_order_clamped_box  # noqa: E402
from splatgl.imagefiles.images import write_image  # noqa: E402
from splatgl.splatmath.project import covariance_3d, quat_to_rotmat  # noqa: E402

SCENES = ("ply/donut_sh0.ply", "compressed_ply/guitar.compressed.ply",
          "compressed_ply/biker.compressed.ply")
PERCENTS = (50, 25, 10, 5)
#: Turns (degrees, about the scene's up through the framed centre) of the three views.
TURNS = (0.0, 120.0, 240.0)
FLOATER_SCENE = "compressed_ply/biker.compressed.ply"
#: Synthetic floaters added to each scene for the floater table.
FLOATERS = 300


def views(scene: Scene, width: int, height: int):
    """The default camera and the same orbit turned by TURNS about the scene's up."""
    import math

    from splatgl.cameras.camera import Camera
    from splatgl.cameras.framing import DEFAULT_ELEVATION, DEFAULT_FOV_Y, _up_vector
    from splatgl.cameras.poses import orbit

    lo, hi = scene.robust_bounds
    centre, radius = (lo + hi) / 2, max(scene.robust_radius, 1e-6)
    fov_y = math.radians(DEFAULT_FOV_Y)
    half = min(2.0 * math.atan(math.tan(fov_y / 2.0) * width / height), fov_y) / 2.0
    distance = 1.05 * radius / math.sin(half)
    up = _up_vector(scene, None)
    return [Camera.from_fov(width, height, DEFAULT_FOV_Y,
                            orbit(centre, distance, 180.0 + turn, DEFAULT_ELEVATION, up))
            for turn in TURNS]


def groups(scene: Scene, target: int) -> Scene:
    """The LOD hierarchy's grouping: consecutive Morton rows, ceil(N / target) per parent."""
    b = -(-scene.count // target)
    order = morton_order_clamped_box(scene.means.astype(np.float64))
    s = scene.subset(order)
    scales = s.scales.astype(np.float64)
    mu, _, opac, _, sh, p_scales, quats, _ = merge_groups(
        s.means.astype(np.float64), covariance_3d(quat_to_rotmat(s.rotations.astype(np.float64)),
                                                  scales),
        s.opacities.astype(np.float64), area_proxy(scales), s.sh.astype(np.float64), b)
    return Scene.from_activated(mu, quats, p_scales, opac, sh)


def prune(scene: Scene, target: int) -> Scene:
    mass = scene.opacities.astype(np.float64) * area_proxy(scene.scales.astype(np.float64))
    return scene.subset(np.sort(np.argsort(-mass, kind="stable")[:target]))


def render_all(r: Renderer, scene: Scene, cams) -> list[np.ndarray]:
    from splatgl.api import default_settings

    return [r.render(scene, cam, default_settings(scene))[..., :3] for cam in cams]


def decimation_table(r: Renderer, width: int, height: int, root: Path) -> list[dict]:
    rows = []
    for name in SCENES:
        scene = load_scene(root / name)
        cams = views(scene, width, height)
        full = render_all(r, scene, cams)
        for pct in PERCENTS:
            target = Decimate(percent=pct).target(scene.count)
            row = {"scene": name, "splats": scene.count, "percent": pct, "target": target}
            for method, make in (("pairs", lambda: apply_operations(scene, [Decimate(percent=pct)]).scene),
                                 ("groups", lambda: groups(scene, target)),
                                 ("prune", lambda: prune(scene, target))):
                small = make()
                got = render_all(r, small, cams)
                row[method] = float(np.mean([psnr(g, f) for g, f in zip(got, full)]))
                row[method + "_count"] = small.count
            rows.append(row)
            print(json.dumps(row), flush=True)
    return rows


def markdown(rows: list[dict]) -> str:
    lines = ["| scene | splats | kept | pairs (edit --decimate) | LOD groups | prune |",
             "|---|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {Path(r['scene']).name} | {r['splats']:,} | {r['percent']}% "
                     f"({r['target']:,}) | {r['pairs']:.2f} dB | {r['groups']:.2f} dB "
                     f"({r['groups_count']:,}) | {r['prune']:.2f} dB |")
    return "\n".join(lines) + "\n"


def with_floaters(scene: Scene, cam, count: int = FLOATERS, seed: int = 0) -> Scene:
    """``scene`` plus ``count`` synthetic floaters: faint (opacity 0.05-0.4) blobs about 1% of
    the scene's size, scattered in the frustum between the camera and the scene, as training
    leaves them in front of the capture cameras (the shared scenes are cleaned captures)."""
    from splatgl.edit import merge_scenes

    rng = np.random.default_rng(seed)
    lo, hi = scene.robust_bounds
    size = float(np.linalg.norm(hi - lo))
    t = rng.uniform(0.2, 0.8, count)[:, None]
    means = cam.center + t * ((lo + hi) / 2 - cam.center) + rng.normal(0, 0.25 * size, (count, 3)) * t
    scales = np.full((count, 3), 0.01 * size) * rng.uniform(0.5, 2.0, (count, 1))
    floaters = Scene.from_activated(means, rng.normal(size=(count, 4)), scales,
                                    rng.uniform(0.05, 0.4, count), rng.normal(0, 0.5, (count, 1, 3)))
    return merge_scenes([scene, floaters])


def _kept(scene: Scene, edited: Scene) -> np.ndarray:
    return np.isin(scene.means.view("V12").ravel(), edited.means.view("V12").ravel())


def floater_table(r: Renderer, width: int, height: int, root: Path) -> list[dict]:
    """Per scene: what the default --remove-floaters removes from the clean scene (and the PSNR
    of its render against the full one), and from the scene with FLOATERS added: how many of
    them it caught, how many real splats went, and the PSNR against the clean scene's render
    before and after.  Pictures of FLOATER_SCENE."""
    from splatgl.api import default_settings

    rows = []
    for name in SCENES:
        scene = load_scene(root / name)
        cam = default_camera(scene, width, height)
        settings = default_settings(scene)
        clean = r.render(scene, cam, settings)
        dirty = with_floaters(scene, cam)
        step = apply_operations(scene, [RemoveFloaters()])
        edited = apply_operations(dirty, [RemoveFloaters()])
        kept = _kept(dirty, edited.scene)
        images = {"before": r.render(dirty, cam, settings),
                  "after": r.render(edited.scene, cam, settings),
                  "removed": r.render(dirty.subset(~kept), cam, settings)}
        rows.append({"scene": name, "splats": scene.count, "parameters": step.steps[0].parameters,
                     "clean_removed": step.steps[0].removed,
                     "clean_psnr": psnr(r.render(step.scene, cam, settings)[..., :3], clean[..., :3]),
                     "added": FLOATERS, "caught": int((~kept[scene.count:]).sum()),
                     "real_removed": int((~kept[:scene.count]).sum()),
                     "dirty_psnr": psnr(images["before"][..., :3], clean[..., :3]),
                     "cleaned_psnr": psnr(images["after"][..., :3], clean[..., :3]),
                     "detail": edited.steps[0].detail})
        print(json.dumps(rows[-1]), flush=True)
        if name == FLOATER_SCENE:
            for label, rgba in images.items():
                write_image(REPO / "docs" / f"editing-floaters-{label}.png", rgba)
    return rows


def floater_markdown(rows: list[dict]) -> str:
    lines = ["| scene | splats | clean scene: removed (PSNR after) | floaters added | caught | "
             "real splats removed | PSNR with floaters | after removal |",
             "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {Path(r['scene']).name} | {r['splats']:,} | {r['clean_removed']:,} "
                     f"({r['clean_psnr']:.1f} dB) | {r['added']} | {r['caught']} | "
                     f"{r['real_removed']} | {r['dirty_psnr']:.1f} dB | {r['cleaned_psnr']:.1f} dB |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--width", type=int, default=640)
    p.add_argument("--height", type=int, default=360)
    p.add_argument("--skip-table", action="store_true")
    args = p.parse_args(argv)
    root = shared_scenes_dir(REPO)
    results = REPO / "docs" / "results"
    with Renderer() as r:
        floaters = floater_table(r, args.width, args.height, root)
        (results / "edit-floaters.md").write_text(floater_markdown(floaters))
        if args.skip_table:
            return 0
        rows = decimation_table(r, args.width, args.height, root)
    payload = {"width": args.width, "height": args.height, "views": list(TURNS),
               "floaters": floaters, "rows": rows}
    (results / "edit-decimate-psnr.json").write_text(json.dumps(payload, indent=2) + "\n")
    (results / "edit-decimate-psnr.md").write_text(markdown(rows))
    print(markdown(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
