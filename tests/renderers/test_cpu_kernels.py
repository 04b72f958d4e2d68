"""The CPU renderer's numba kernels against their NumPy twins in :mod:`splatgl.splatmath`, as
tests/splatmath/test_twins.py and tests/gl/test_shaders.py hold the shaders to theirs; and no kernel or
shader retypes a constant of :mod:`splatgl.constants`.

Stage 1 (:mod:`splatgl.renderers._cpu_project`: ``project_pinhole``, ``project_model`` and their
``_finish``, ``_sh_color``) runs on seeded random splats and is compared row by row with
:func:`splatgl.splatmath.project.project` in float32 on the same anchored means: pixel
position, conic, opacity (antialiased or not), SH colour of every degree and depth agree to a
few float32 ulps (the kernels order a few operations differently; measured worst relative
differences: conic 7.5e-6, antialiased opacity 1.1e-5 (its determinant ratio cancels), the
rest 0; bounds 4x that), every row the kernel keeps is one the twin's rules keep, and
its tile rectangle lies inside the twin's ``ceil(3 sqrt(lambda_max))`` rectangle.  The
blending kernel (``_cpu_raster._blend_row``) is compared with
:func:`splatgl.splatmath.blend.blend_front_to_back` on one row of pixels.
"""

from __future__ import annotations

import ast
import math
import re
from pathlib import Path

import numpy as np
import pytest

from helpers import IN_DEPTH, random_scene, view_of
from splatgl import constants
from splatgl.cameras.camera import Camera
from splatgl.cameras.fisheye import Fisheye
from splatgl.cameras.view import anchored_camera
from splatgl.gl.shaders import shader_dir
from splatgl.scene.settings import RenderSettings
from splatgl.reference.stages import tile_grid
from splatgl.splatmath import blend as bl
from splatgl.splatmath import project as pm

REPO = Path(__file__).resolve().parents[2]
#: Modules compiled by numba: they must import every reference constant they use.
KERNEL_MODULES = ["splatgl/renderers/_cpu_project.py", "splatgl/renderers/_cpu_raster.py",
                  "splatgl/order/kernels.py", "splatgl/order/_numba_cull.py",
                  "splatgl/lod/_cut_numba.py"]
CAM = Camera.from_fov(160, 112, 60.0)


def _reference_constants() -> dict[str, float]:
    """The float constants of :mod:`splatgl.constants` that a literal could only mean, by name,
    SH tables included: not whole or half numbers (0.5, 3.0) nor powers of ten (1e-4, 0.01),
    which are also ordinary arithmetic and tolerances."""
    out = {}
    for name, value in vars(constants).items():
        values = value if isinstance(value, tuple) else (value,)
        for i, v in enumerate(values):
            if (isinstance(v, float) and v > 0 and math.isfinite(v) and 2.0 * v != round(2.0 * v)
                    and not math.isclose(10.0 ** round(math.log10(v)), v)):
                out[name if len(values) == 1 else f"{name}[{i}]"] = v
    out["MAX_RADIUS"] = constants.MAX_RADIUS
    return out


def _retyped(values: list[float], known: dict[str, float]) -> list[str]:
    return sorted({f"{v!r} (= {name})" for v in values for name, c in known.items()
                   if v != 0 and math.isclose(v, c, rel_tol=1e-9)})


@pytest.mark.parametrize("path", KERNEL_MODULES)
def test_kernels_import_the_reference_constants_instead_of_retyping_them(path):
    """No name of splatgl.constants is assigned in a kernel module, and no number written
    there (outside docstrings) equals a reference constant."""
    tree = ast.parse((REPO / path).read_text())
    assigned = {t.id for node in ast.walk(tree) if isinstance(node, (ast.Assign, ast.AnnAssign))
                for t in (node.targets if isinstance(node, ast.Assign) else [node.target])
                if isinstance(t, ast.Name)}
    shadowed = sorted(assigned & {n for n in vars(constants) if n.isupper()})
    assert not shadowed, f"{path} retypes {shadowed}: import them from splatgl.constants"
    numbers = [float(n.value) for n in ast.walk(tree)
               if isinstance(n, ast.Constant) and type(n.value) in (int, float)]
    numbers += [float(eval(compile(ast.Expression(n), path, "eval")))   # 2 ** 52 and the like
                for n in ast.walk(tree) if isinstance(n, ast.BinOp)
                and all(isinstance(c, ast.Constant) for c in (n.left, n.right))
                and type(n.left.value) in (int, float) and type(n.right.value) in (int, float)]
    found = _retyped(numbers, _reference_constants())
    assert not found, f"{path} retypes reference constants: {found}"


def test_shaders_take_the_reference_constants_from_the_generated_defines():
    """Shader code (comments stripped) writes no reference constant as a literal: it uses the
    ``#define`` :func:`splatgl.constants.glsl_defines` generates."""
    known = {k: v for k, v in _reference_constants().items() if k != "MAX_RADIUS"}
    bad = []
    for path in sorted(p for p in shader_dir().rglob("*") if p.suffix in (".glsl", ".comp", ".vert", ".frag")):
        code = re.sub(r"/\*.*?\*/", "", path.read_text(), flags=re.S)
        code = "\n".join(line.split("//")[0] for line in code.splitlines())
        literals = [float(m) for m in re.findall(r"(?<![\w.])(\d+\.\d*(?:[eE][-+]?\d+)?|\d+[eE][-+]?\d+)", code)]
        bad += [f"{path.name}: {x}" for x in _retyped(literals, known)]
    assert not bad, "\n".join(bad)


def test_max_radius_is_the_constant_in_the_kernel_and_its_twin():
    numba = pytest.importorskip("numba")  # noqa: F841
    from splatgl.renderers import _cpu_project

    assert _cpu_project.MAX_RADIUS is constants.MAX_RADIUS is pm.MAX_RADIUS


# ------------------------------------------------------------------ stage 1 against its twin
def _stage1(scene, camera, settings):
    """(kernel outputs, anchored camera, float32 means relative to the anchor)."""
    pytest.importorskip("numba", reason="the CPU kernels need numba (the fast extra)")
    from splatgl.renderers import cpu

    view = view_of(camera, scene, settings)
    stage1 = cpu.CpuRenderer(scene, settings).stage1
    run = stage1.pinhole if isinstance(camera.model, type(CAM.model)) else stage1.model
    out = run(view, [(0, scene.count // 2), (scene.count // 2, scene.count)])
    return out, anchored_camera(view.camera, view.anchor), stage1.relative_means(view.anchor)


def _twin(scene, cam, rel, settings):
    f32 = np.float32
    return pm.project(rel, scene.rotations.astype(f32), scene.scales.astype(f32),
                      scene.opacities.astype(f32), scene.sh.astype(f32), cam,
                      antialias=settings.antialias, sh_degree=settings.sh_degree)


def _close(got, want, rtol, scale):
    got, want = np.asarray(got, np.float64), np.asarray(want, np.float64)
    err = np.abs(got - want) / (np.abs(want) + scale)
    assert float(err.max()) <= rtol, f"worst relative difference {float(err.max()):.3g} > {rtol}"


@pytest.mark.parametrize("degree,antialias,camera", [
    (0, False, CAM), (3, True, CAM), (2, False, Camera.of_model(Fisheye, 128, 128, 160.0))],
    ids=["pinhole", "pinhole-sh3-antialias", "fisheye-sh2"])
def test_stage1_kernels_match_their_numpy_twin(degree, antialias, camera):
    scene = random_scene(2000, 31 + degree, degree=degree, **IN_DEPTH)
    settings = RenderSettings(antialias=antialias)
    (mean2d, conic, opacity, reach, color, depth, box, rect), cam, rel = _stage1(scene, camera, settings)
    twin = _twin(scene, cam, rel, settings)
    kept = np.flatnonzero((rect[:, 1] > rect[:, 0]) & (rect[:, 3] > rect[:, 2]))
    assert kept.size > 500
    near = view_of(camera, scene, settings).near_in(np.float32)
    assert cam.model.visible(twin.p_cam[kept], cam, near).all() and (twin.det[kept] > 0).all()
    _close(mean2d[kept], twin.mean2d[kept], 2e-6, 1.0)
    _close(conic[kept], twin.conic[kept], 3e-5, np.abs(twin.conic[kept]).max(axis=1, keepdims=True))
    _close(opacity[kept], twin.opacity[kept], 5e-5, 0.0)
    _close(color[kept], twin.color[kept], 2e-6, 1.0)
    _close(depth[kept], twin.depth[kept], 1e-6, 0.0)
    np.testing.assert_allclose(reach[kept], 2.0 * np.log(255.0 * twin.opacity[kept].astype(np.float64)),
                               rtol=1e-5, atol=1e-5)
    # the tile rectangle: inside the twin's reference extent ceil(3 sqrt(lambda_max)) (3DGS getRect)
    r = pm.reference_radius(twin.cov2d[kept].astype(np.float64)).astype(np.float64)
    p = twin.mean2d[kept].astype(np.float64) - 0.5
    gx, gy = tile_grid(cam.width, cam.height)
    lo = np.clip(np.trunc((p - r[:, None]) / 16), 0, (gx, gy))
    hi = np.clip(np.trunc((p + r[:, None] + 15) / 16), 0, (gx, gy))
    assert (rect[kept, 0] >= lo[:, 0]).all() and (rect[kept, 1] <= hi[:, 0]).all()
    assert (rect[kept, 2] >= lo[:, 1]).all() and (rect[kept, 3] <= hi[:, 1]).all()


def test_blend_row_kernel_matches_the_blending_twin():
    """Eight splats blended front to back over a 32-pixel row by ``_blend_row`` (run as
    Python) equal :func:`splatgl.splatmath.blend.splat_alpha` and ``blend_front_to_back``."""
    pytest.importorskip("numba", reason="the CPU kernels need numba (the fast extra)")
    from splatgl.renderers import _cpu_raster as raster

    rng = np.random.default_rng(5)
    f32, n, width = np.float32, 8, 32   # T stays above 1e-4: no early stop
    mean2d = np.c_[rng.uniform(0, width, n), np.full(n, 0.5)].astype(f32)
    conic = np.c_[rng.uniform(0.01, 0.3, n), np.zeros(n), np.full(n, 0.1)].astype(f32)
    opacity = rng.uniform(0.05, 0.6, n).astype(f32)
    color = rng.uniform(0, 1, (n, 3)).astype(f32)
    alpha = bl.splat_alpha(mean2d, conic, opacity, width, 1)
    want = bl.blend_front_to_back(alpha, color)                    # (1, W, 4) premultiplied RGBA
    acc = [np.zeros(width, f32) for _ in range(4)]
    trans = np.ones(width, f32)
    for i in range(n):
        raster._blend_row.py_func(*acc, trans, 0, width, 0, width, f32(0.5) - mean2d[i, 0],
                                  f32(-0.5) * conic[i, 0], f32(0.0), f32(0.0), opacity[i],
                                  *color[i], f32(1.0))
    np.testing.assert_allclose(np.c_[acc[0], acc[1], acc[2]], want[0, :, :3], rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(1.0 - np.abs(trans), want[0, :, 3], rtol=1e-5, atol=1e-6)
