"""Library first, CLI thin (issue 26, item 5): each rule ``splatgl render`` applies lives in the
library, so the Python API refuses, frames and defaults as the command line does.

Each test runs one rule both ways: through the Python API and through ``splatgl.cli.main``,
and asserts the same message, camera or setting.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import splatgl
from helpers import IN_VIEW, random_scene
from splatgl.cli import build_parser, main
from splatgl.commands._common import camera_from_args, demo_scene_path, settings_from_args
from splatgl.errors import CameraError, SplatglError
from splatgl.formats import save_scene
from splatgl.output.images import read_image

DEMO = demo_scene_path()


def cli_error(capsys, *argv) -> str:
    """The one error line ``splatgl ARGV`` prints (exit code 2), without its prefix."""
    assert main([str(a) for a in argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith("splatgl: error: ") and err.count("\n") == 1, err
    return err[len("splatgl: error: "):-1]


def cli_camera(*argv, scene=None):
    """The camera ``splatgl render ARGV`` renders (of ``scene``, default the demo)."""
    args = build_parser().parse_args(["render", *map(str, argv), "-o", "x.png"])
    scene = scene if scene is not None else splatgl.load_scene(args.scene or DEMO)
    return camera_from_args(args, scene, settings_from_args(args))


# ------------------------------------------------------------------ convention gsplat


@pytest.mark.parametrize("kind", ["quad", "tile"])
def test_gpu_renderers_refuse_the_gsplat_convention_as_the_cli_does(kind, capsys, tmp_path):
    """The quad and tile renderers draw the inria rules only: RenderSettings(convention=gsplat)
    was ignored silently by the library (only the CLI refused it)."""
    scene = random_scene(50, **IN_VIEW)
    camera = splatgl.Camera.from_fov(32, 24, 60.0)
    gsplat = splatgl.RenderSettings(convention="gsplat")
    with pytest.raises(SplatglError) as api:
        splatgl.render(scene, camera, gsplat, kind=kind)
    with splatgl.Renderer() as r, pytest.raises(SplatglError) as many:
        next(r.render_many(scene, [camera], gsplat, kind))
    line = cli_error(capsys, "render", "--convention", "gsplat", "--renderer", kind,
                     "--width", 32, "--height", 24, "-o", tmp_path / "x.png")
    assert str(api.value) == str(many.value) == line == (
        f"--convention gsplat applies to the NumPy reference only; the {kind} renderer follows "
        "the inria rules (use --renderer reference)")
    rgba = splatgl.render(scene, camera, gsplat, kind="reference")   # the reference draws it
    assert rgba.shape == (24, 32, 4) and rgba[..., 3].max() > 0.1


def test_compare_draws_the_gpu_side_with_the_inria_rules(capsys):
    """compare --convention gsplat measures the quad path (inria rules) against the gsplat
    reference: the library's refusal must not stop it."""
    assert main(["compare", "--convention", "gsplat", "--width", "48", "--height", "32",
                 "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["psnr"] > 20.0


def test_eval_refuses_the_gsplat_convention_before_the_work(capsys, tmp_path):
    """eval took --convention gsplat with the quad renderer and drew the inria rules."""
    line = cli_error(capsys, "eval", "--dataset", tmp_path / "none", "--convention", "gsplat")
    assert line.startswith("--convention gsplat applies to the NumPy reference only; the quad")
