"""splatgl convert and conversion_error: exact PLY round trips, .splat within its quantisation,
real compressed/SPZ/ksplat files to PLY exactly, and the CLI's refusals (exit 2, nothing written).

.splat quantisation bounds (see splatgl/formats/splat.py), derived per attribute:

- position: stored as float32, so exact (0).
- scale: stored linear as float32 ``v = exp(l)(1 + d1)`` and read back as ``l' = fl32(ln v)``:
  ``|l' - l| <= |d1| + 2^-24 (|l| + |d1|)`` with ``|d1| <= 2^-24`` (float32 rounding), so the
  relative scale error ``|exp(l' - l) - 1| <= 2^-24 (1 + |l|) (1 + 1e-6)``.
- opacity: 8-bit alpha ``rint(255 o)``: error <= 0.5/255, plus float32 rounding of the opacity
  and of the logit read back (< 1e-6).
- colour: 8-bit ``rint(255 (0.5 + SH_C0 f_dc))`` clipped to 0..255, so against the clipped input
  colour the error is <= 0.5/255 (f_dc error <= 0.5/255/SH_C0), plus float32 rounding (< 1e-6).
- rotation: each unit-quaternion component becomes ``clip(rint(128 q + 128), 0, 255)``, read
  as ``(b - 128)/128``: error <= 0.5/128 per component, except a component near +1 which clips
  to 127/128 (error <= 1/128; the other three are then near 0, error <= 0.5/128 each).  So
  ``|q' - q| <= sqrt(1 + 3/4)/128``; for unit ``q`` the 4D angle between ``q`` and ``q'`` is at
  most ``asin(|q' - q|)`` and the rotation angle twice that: <= 1.1845 degrees.
"""

from __future__ import annotations

import json
import math
import warnings

import numpy as np
import pytest

from helpers import random_scene, shared_file
from splatgl.cli import main
from splatgl.constants import SH_C0
from splatgl.formats.convert import conversion_error, convert, rotation_angle_deg
from splatgl.errors import SplatglError
from splatgl.formats import load_scene, save_scene
from splatgl.scene.splats import Scene, SplatKind

SPLAT_ROTATION_BOUND_DEG = math.degrees(2.0 * math.asin(math.sqrt(1.75) / 128.0))
SPLAT_OPACITY_BOUND = 0.5 / 255.0 + 1e-6
SPLAT_COLOR_BOUND = 0.5 / 255.0 + 1e-6

#: Real files whose decoded values a PLY must hold exactly (relative to the shared scenes).
REAL_FILES = [
    "ply/donut_sh0.ply",
    "compressed_ply/biker.compressed.ply",
    "compressed_ply/guitar.compressed.ply",
    "spz/biker_v4.spz",
    "spz/donut_sh0_v2.spz",
    "fixtures/test64_sh3.compressed.ply",
    "fixtures/minimal.splat",
    "fixtures/minimal.ksplat",
    "fixtures/minimal-v2.spz",
    "fixtures/minimal-v3.spz",
    "fixtures/minimal-v4.spz",
    "fixtures/minimal-raw.spz",
]


def same_values(a: Scene, b: Scene) -> None:
    for name in ("means", "quats", "log_scales", "opacity_logits", "sh"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert a.kind is b.kind


# --- conversion_error ----------------------------------------------------------------------


def test_conversion_error_identical_is_zero_and_bit_exact():
    s = random_scene(50, degree=3)
    e = conversion_error(s, s)
    assert e["bit_exact"] and e["count"] == 50 and e["sh_degree"] == [3, 3]
    for key in ("position", "scale", "opacity", "rotation", "color", "sh_rest"):
        assert e[key] == {"max": 0.0, "mean": 0.0}, key


def test_rotation_angle_treats_q_and_minus_q_alike_and_is_exact_near_zero():
    q = np.array([[1.0, 0, 0, 0], [0.3, -0.2, 0.9, 0.1]])
    np.testing.assert_array_equal(rotation_angle_deg(q, -q), [0.0, 0.0])
    half = math.radians(0.001) / 2  # 0.001 degree about z
    r = np.array([[math.cos(half), 0, 0, math.sin(half)]])
    assert rotation_angle_deg(q[:1], r)[0] == pytest.approx(0.001, rel=1e-9)
    r90 = np.array([[-math.cos(math.pi / 4), 0, -math.sin(math.pi / 4), 0]])
    assert rotation_angle_deg(q[:1] * 3.0, r90)[0] == pytest.approx(90.0, rel=1e-12)


def test_conversion_error_units():
    a = random_scene(20, degree=1)
    dc = a.sh.copy()
    dc[:, 0] += 1.0 / 255.0 / SH_C0  # one 8-bit colour step
    b = Scene(a.means + np.float32([3, 4, 0]), a.quats, a.log_scales + np.float32(np.log(1.5)),
              a.opacity_logits, dc)
    e = conversion_error(a, b)
    assert e["position"]["max"] == pytest.approx(5.0, rel=1e-5)
    assert e["scale"]["mean"] == pytest.approx(0.5, rel=1e-5)
    assert e["color"]["max"] == pytest.approx(1.0 / 255.0, rel=1e-3)
    assert e["opacity"]["max"] == 0.0 and e["rotation"]["max"] == 0.0 and not e["bit_exact"]
    with pytest.raises(SplatglError):
        conversion_error(a, a.subset(np.arange(10)))


# --- round trips ----------------------------------------------------------------------------


@pytest.mark.parametrize("kind", list(SplatKind))
def test_ply_to_ply_is_bit_exact(tmp_path, kind):
    src = tmp_path / "in.ply"
    scene = random_scene(500, degree=3, kind=kind)
    save_scene(src, scene)
    result = convert(src, tmp_path / "out.ply")
    assert result.error["bit_exact"]
    same_values(scene, load_scene(tmp_path / "out.ply"))


def test_ply_to_splat_to_ply_within_quantisation(tmp_path):
    scene = random_scene(2000, degree=3, seed=1)
    save_scene(tmp_path / "in.ply", scene)
    with pytest.warns(UserWarning, match="SH degree 0 only"):
        result = convert(tmp_path / "in.ply", tmp_path / "mid.splat")
    assert result.sh_degree_in == 3 and result.sh_degree_out == 0
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # degree 0 now: nothing more to drop, no warning
        convert(tmp_path / "mid.splat", tmp_path / "out.ply")
    back = load_scene(tmp_path / "out.ply")
    assert back.sh_degree == 0

    e = conversion_error(scene, back)
    assert e["position"]["max"] == 0.0
    assert e["opacity"]["max"] <= SPLAT_OPACITY_BOUND
    assert e["rotation"]["max"] <= SPLAT_ROTATION_BOUND_DEG
    assert e["sh_rest"] is None
    rel = np.abs(np.expm1(back.log_scales.astype(np.float64) - scene.log_scales))
    assert np.all(rel <= 2.0 ** -24 * (1.0 + np.abs(scene.log_scales)) * (1.0 + 1e-6))
    colour_in = np.clip(0.5 + SH_C0 * scene.sh[:, 0].astype(np.float64), 0.0, 1.0)
    colour_back = 0.5 + SH_C0 * back.sh[:, 0].astype(np.float64)
    assert np.abs(colour_back - colour_in).max() <= SPLAT_COLOR_BOUND
    inside = np.abs(scene.sh[:, 0].astype(np.float64) * SH_C0) <= 0.5
    assert e["color_outside_01"] == int((~inside).sum()) > 0
    f_dc_err = np.abs(back.sh[:, 0] - scene.sh[:, 0].astype(np.float64))[inside]
    assert f_dc_err.max() <= 0.5 / 255.0 / SH_C0 + 1e-5


def test_sh_degree_option_caps_the_bands(tmp_path):
    scene = random_scene(100, degree=3)
    save_scene(tmp_path / "in.ply", scene)
    result = convert(tmp_path / "in.ply", tmp_path / "out.ply", sh_degree=1)
    back = load_scene(tmp_path / "out.ply")
    assert result.sh_degree_out == 1 and back.sh_degree == 1
    np.testing.assert_array_equal(back.sh, scene.sh[:, :4])
    assert result.error["sh_rest"] == {"max": 0.0, "mean": 0.0}


@pytest.mark.parametrize("name", REAL_FILES)
def test_real_file_to_ply_holds_the_decoded_values_exactly(shared_scenes, tmp_path, name):
    src = shared_file(shared_scenes, name)
    original = load_scene(src)
    result = convert(src, tmp_path / "out.ply")
    assert result.error["bit_exact"] and result.count == original.count
    same_values(original, load_scene(tmp_path / "out.ply"))


@pytest.mark.parametrize("name", ["ply/donut_sh0.ply", "compressed_ply/biker.compressed.ply",
                                  "spz/biker_v4.spz", "fixtures/test64_sh3.compressed.ply"])
def test_real_file_to_splat_within_quantisation(shared_scenes, tmp_path, name):
    src = shared_scenes / name
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # test64 has SH degree 3: dropped with a warning
        e = convert(src, tmp_path / "out.splat").error
    assert e["position"]["max"] == 0.0
    assert e["opacity"]["max"] <= SPLAT_OPACITY_BOUND
    assert e["rotation"]["max"] <= SPLAT_ROTATION_BOUND_DEG
    assert e["scale"]["max"] <= 2.0 ** -24 * 50
    if e["color_outside_01"] == 0:
        assert e["color"]["max"] <= SPLAT_COLOR_BOUND


# --- the command line -----------------------------------------------------------------------


def run_cli(capsys, *argv):
    code = main(["convert", *map(str, argv)])
    out, err = capsys.readouterr()
    return code, out, err


def test_cli_writes_and_reports(tmp_path, capsys):
    save_scene(tmp_path / "in.ply", random_scene(200, degree=2))
    code, out, err = run_cli(capsys, tmp_path / "in.ply", tmp_path / "out.splat")
    assert code == 0
    assert "wrote" in out and "rotation" in out and "degrees" in out and "SH rest" in out
    assert "warning" in err and "SH degree 0 only" in err
    code, out, _ = run_cli(capsys, tmp_path / "out.splat", tmp_path / "back.ply", "--json")
    assert code == 0
    report = json.loads(out)
    assert report["splats"] == 200 and report["output_format"] == "ply"
    assert report["error"]["bit_exact"] is True


def test_cli_missing_input_exits_2_and_writes_nothing(tmp_path, capsys):
    code, out, err = run_cli(capsys, tmp_path / "nope.ply", tmp_path / "out.ply")
    assert code == 2 and "no such file" in err and err.count("\n") == 1
    assert list(tmp_path.iterdir()) == []


def test_cli_unsupported_output_exits_2(tmp_path, capsys):
    save_scene(tmp_path / "in.ply", random_scene(10, degree=3))
    code, _, err = run_cli(capsys, tmp_path / "in.ply", tmp_path / "out.ksplat")
    assert code == 2 and "cannot write this format" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.ply"]


def test_cli_refuses_to_overwrite_without_force(tmp_path, capsys):
    save_scene(tmp_path / "in.ply", random_scene(10, degree=3))
    (tmp_path / "out.ply").write_bytes(b"keep me")
    code, _, err = run_cli(capsys, tmp_path / "in.ply", tmp_path / "out.ply")
    assert code == 2 and "exists (use --force to replace it)" in err and "--force" in err
    assert (tmp_path / "out.ply").read_bytes() == b"keep me"
    code, _, _ = run_cli(capsys, tmp_path / "in.ply", tmp_path / "out.ply", "--force")
    assert code == 0
    same_values(load_scene(tmp_path / "in.ply"), load_scene(tmp_path / "out.ply"))


def test_cli_failed_write_leaves_nothing_half_written(tmp_path, capsys):
    save_scene(tmp_path / "in.ply", random_scene(10, degree=3, kind=SplatKind.SURFEL_2D))
    code, _, err = run_cli(capsys, tmp_path / "in.ply", tmp_path / "out.splat")
    assert code == 2 and "surfel" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.ply"]  # no out, no .partial


def test_cli_bad_input_values_need_drop_invalid(tmp_path, capsys):
    from splatgl.formats.ply_write import scene_to_vertices, write_elements

    rows = scene_to_vertices(random_scene(10, degree=0))
    rows["x"][3] = np.nan
    write_elements(tmp_path / "in.ply", [("vertex", rows)])
    code, _, err = run_cli(capsys, tmp_path / "in.ply", tmp_path / "out.ply")
    assert code == 2 and "--drop-invalid" in err and not (tmp_path / "out.ply").exists()
    code, out, err = run_cli(capsys, tmp_path / "in.ply", tmp_path / "out.ply", "--drop-invalid")
    assert code == 0 and "dropped 1 invalid row" in err
    assert load_scene(tmp_path / "out.ply").count == 9
