"""Scenes with extreme stored values (log-scales of 100 or 1000, SH or positions near float32's
largest) load, convert and render without a raw NumPy warning or a traceback; a format that
cannot hold such a value refuses in one line naming the file, field and row, before writing
(issue 38, item 4: log-scales leaked NumPy warnings)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from helpers import random_scene
from splatgl.cli import main
from splatgl.formats import load_scene, save_scene
from splatgl.scene.splats import Scene


def extreme(path, log_scale=None, sh=None, position=None):
    """A 20-splat PLY with row 3's log-scales, SH or position set to the given value."""
    s = random_scene(20, degree=1)
    means, logs, coeffs = s.means.copy(), s.log_scales.copy(), s.sh.copy()
    if log_scale is not None:
        logs[3] = log_scale
    if sh is not None:
        coeffs[3] = sh
    if position is not None:
        means[3] = position
    save_scene(path, Scene(means, s.quats, logs, s.opacity_logits, coeffs))
    return path


def cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize("log_scale", [100.0, 1000.0, -1000.0])
def test_huge_log_scales_load_without_a_warning(tmp_path, capsys, log_scale):
    path = extreme(tmp_path / "s.ply", log_scale=log_scale)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # log-scale 100: "overflow encountered in cast"
        scene = load_scene(path)
        big = scene.scales[3]
        rows = scene.activated_rows(0, scene.count)
    assert (np.isinf(big) if log_scale > 0 else big == 0).all()
    assert np.array_equal(rows.scales, scene.scales)
    code, out, err = cli(capsys, "info", path)
    assert code == 0 and err == "", err


@pytest.mark.parametrize("name", ["o.spz", "o.compressed.ply", "o.sog"])
def test_formats_that_clip_log_scales_report_an_infinite_error_without_a_warning(tmp_path, capsys,
                                                                                 name):
    path = extreme(tmp_path / "s.ply", log_scale=-1000.0)  # math.expm1 raised OverflowError
    code, out, err = cli(capsys, "convert", path, tmp_path / name)
    assert code == 0 and err == "", err
    if name != "o.sog":  # SOG's codebook holds 1000 itself
        assert "  scale        inf / inf (bound inf) (relative)" in out.splitlines(), out


@pytest.mark.parametrize("name,fmt", [("o.splat", ".splat"), ("o.glb", "glTF"), ("o.gltf", "glTF")])
@pytest.mark.parametrize("log_scale", [100.0, -1000.0])
def test_formats_of_linear_scales_refuse_what_they_cannot_hold(tmp_path, capsys, name, fmt,
                                                               log_scale):
    """They wrote inf or 0, and the file they wrote was then refused when read back."""
    path = extreme(tmp_path / "s.ply", log_scale=log_scale)
    code, out, err = cli(capsys, "convert", path, tmp_path / name, "--sh-degree", "0")
    assert code == 2 and err == (
        f"splatgl: error: {tmp_path / name}: field 'scale': row 3: log-scale {log_scale:g} is "
        f"beyond what the {fmt} format's linear float32 scales hold (e^-103 to e^88); write "
        ".ply, which stores log-scales\n"), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.ply"]


def test_sog_writes_sh_near_float32s_largest_without_a_warning(tmp_path):
    path = extreme(tmp_path / "s.ply", sh=3e38)
    scene = load_scene(path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # "overflow encountered in reduce / add / matmul"
        order = save_scene(tmp_path / "o.sog", scene)
    back = load_scene(tmp_path / "o.sog")
    assert back.sh[np.flatnonzero(order == 3)[0], 1:].max() == pytest.approx(3e38, rel=0.01)


def test_spz_names_the_file_when_positions_do_not_fit(tmp_path, capsys):
    path = extreme(tmp_path / "s.ply", position=3e38)
    code, _, err = cli(capsys, "convert", path, tmp_path / "o.spz")
    assert code == 2 and err == (
        f"splatgl: error: {tmp_path / 'o.spz'}: field 'position': positions up to 3e+38 do not "
        "fit SPZ's 24-bit fixed point even with 0 fractional bits\n"), err


def test_a_level_of_detail_of_scales_beyond_float32_is_refused_in_one_line(tmp_path, capsys):
    """It printed a NumPy warning, then a LinAlgError traceback."""
    path = extreme(tmp_path / "s.ply", log_scale=100.0)
    code, _, err = cli(capsys, "lod", path, "-o", tmp_path / "s.lod.ply")
    assert code == 2 and err == (
        "splatgl: error: level of detail: splat 3 has a scale above e^88 world units, whose "
        "moments overflow: remove such splats first (splatgl edit --remove 'max_scale > 1e38')\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.ply"]
