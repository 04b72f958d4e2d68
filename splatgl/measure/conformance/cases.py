"""The conformance kit's cases: scenes, cameras and settings any splat renderer can render, each
with the tolerance that decides pass or fail (docs/fidelity.md, :mod:`splatgl.measure.conformance`).

Cases: a selection of the stress cases (:mod:`splatgl.measure.stress.cases`) that a renderer following
the 3DGS rules must draw (scales, needles, the near plane, the border, far from the origin, wide
and narrow fields of view, orthographic zoom, opacity extremes, 10,000 coincident layers, a
fisheye and a panorama seam, edge-on 2DGS surfels); ``depth_range``, two overlapping splats
1e-3 apart in depth with one splat 1000 units away (16-bit depth buckets tie them); the bundled
demo scene through every camera model; and, where the shared real scenes are present, donut,
guitar and biker from their default cameras.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from ...api import default_camera
from ..bench.real_scenes import shared_scenes_dir
from ...cameras.camera import Camera
from ...scene.splats import Scene
from ...scene.settings import RenderSettings, resolve_near
from ..stress.build import front_camera, splats
from ..stress.cases import case_by_name

#: A case passes when its PSNR against the reference is at least MIN_PSNR dB and at most
#: MAX_OFF_4 of its pixels differ by more than 4/255 in some channel.  40 dB: an 8-bit PNG's
#: rounding alone costs about 59 dB on a full-range image, and splatgl's quad path, which differs
#: from the reference by its missing early stop, its extent and the tile rectangle's tails,
#: scores 66-89 dB on the real scenes (docs/results/summary.md); a flipped image, a bucketed sort that ties
#: overlapping splats or an extent of sqrt(8) sigma score far below.
MIN_PSNR = 40.0
MAX_OFF_4 = 0.01

#: The stress cases in the kit (others need renderer-specific settings, are too large, or hold
#: values a PLY reader refuses, as opacity_extremes' infinite logits).
STRESS = ("scales", "aniso_45", "near_plane", "border", "far_1e6", "fov_170", "ortho_huge_zoom",
          "coincident_10k", "fisheye_90", "equirect_seam", "surfels_edge_on")
#: The demo scene's size per camera model.
DEMO_SIZES = {"perspective": (160, 120), "orthographic": (160, 120), "fisheye": (128, 128),
              "equirectangular": (192, 96)}
#: Real scenes (relative to the shared folder) and the up axis each is shown with.
REAL = (("ply/donut_sh0.ply", "+z"), ("compressed_ply/guitar.compressed.ply", None),
        ("compressed_ply/biker.compressed.ply", None))
REAL_SIZE = (256, 144)


@dataclass(frozen=True)
class Case:
    """One case: ``name``, a one-line ``what``, the ``scene`` and ``camera``, the reference's
    ``settings`` (near plane explicit), and its tolerance."""

    name: str
    what: str
    scene: Scene
    camera: Camera
    settings: RenderSettings
    min_psnr: float = MIN_PSNR
    max_off_4: float = MAX_OFF_4
    tags: tuple[str, ...] = field(default_factory=tuple)


def _explicit_near(scene: Scene, settings: RenderSettings) -> RenderSettings:
    """``settings`` with the near plane splatgl would use written out (other renderers have
    their own default; the kit states it)."""
    import dataclasses
    return dataclasses.replace(settings, near=resolve_near(settings, scene.robust_radius))


def depth_range_case() -> Case:
    """Two overlapping splats 1e-3 apart in depth, the farther one first in the file, and one
    splat 1000 units away: exact depth keys blend the nearer first; 65536 buckets between 4 and
    1000 are 0.015 deep, so bucketed keys tie the two and keep file order."""
    cam = front_camera(4.0, 50.0, 96, 72)
    scene = splats([[0.02, 0.0, 0.001], [0.0, 0.01, 0.0], [0.0, 0.0, 1000.0]],
                   [[0.4, 0.3, 0.05], [0.35, 0.4, 0.05], [60.0, 60.0, 60.0]],
                   opacities=[0.9, 0.9, 0.9],
                   rgb=[[0.9, 0.2, 0.1], [0.1, 0.3, 0.9], [0.3, 0.8, 0.3]])
    return Case("depth_range", "two overlapping splats 1e-3 apart in depth, one 1000 units away "
                "(16-bit depth keys tie the two)", scene, cam,
                _explicit_near(scene, RenderSettings()), tags=("sort",))


def stress_cases() -> list[Case]:
    out = []
    for name in STRESS:
        case = case_by_name(name)
        setup = case.build()
        if setup.expected_scene is not None:
            continue                     # a renderer-specific rule decides what is drawn
        settings = _explicit_near(setup.scene, RenderSettings(near=setup.settings.near,
                                                              background=setup.settings.background))
        tags = ("stress",) + (("2dgs",) if setup.scene.kind.value != "3dgs" else ())
        out.append(Case(f"stress_{name}", case.what, setup.scene, setup.camera, settings, tags=tags))
    return out


def demo_cases(demo: Scene) -> list[Case]:
    out = []
    for model, (w, h) in DEMO_SIZES.items():
        cam = default_camera(demo, w, h, projection=model)
        out.append(Case(f"demo_{model}", f"the bundled demo scene, {model} camera", demo, cam,
                        _explicit_near(demo, RenderSettings()), tags=("camera",)))
    return out


def real_cases(root: Path | None = None) -> list[Case]:
    from ...formats import load_scene
    from ...cameras.up import resolve_up

    root = shared_scenes_dir() if root is None else root
    out = []
    for rel, up in REAL:
        path = root / rel
        if not path.is_file():
            continue
        scene = load_scene(path)
        up_vec, _ = resolve_up(up, path)
        cam = default_camera(scene, *REAL_SIZE, up=up_vec)
        out.append(Case(f"real_{path.name.split('.')[0]}", f"{rel} from its default camera", scene,
                        cam, _explicit_near(scene, RenderSettings()), tags=("real",)))
    return out


def missing_real(root: Path | None = None) -> list[str]:
    """The real scenes (paths relative to the shared folder) not found there: their cases are
    left out of the kit, which ``export`` says."""
    root = shared_scenes_dir() if root is None else root
    return [rel for rel, _ in REAL if not (root / rel).is_file()]


def all_cases(demo: Scene, real: bool = True, stress: bool = True) -> list[Case]:
    """Every case of the kit (real scenes only where the shared folder has them)."""
    out = [depth_range_case()] + demo_cases(demo)
    if stress:
        out += stress_cases()
    if real:
        out += real_cases()
    return out
