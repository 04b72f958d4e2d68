"""Failed writes (a full disk, simulated deterministically by the ``full_disk`` fixture) give
one line naming the user's file, exit code 2 and nothing half-written; a damaged file is never
taken for a complete one."""

from __future__ import annotations

import numpy as np
import pytest

from splatgl.cli import main
from splatgl.commands._common import demo_scene_path
from splatgl.errors import SplatglError
from splatgl.image_io import image_file_problem, read_image, write_image

SIZE = ["--width", "96", "--height", "64"]


def _image(h=64, w=96):
    return np.random.default_rng(0).random((h, w, 4)).astype(np.float32)


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    return err


@pytest.mark.parametrize("ext", ["png", "tif", "exr"])
def test_a_short_write_raises_naming_the_target_and_leaves_nothing(tmp_path, full_disk, ext):
    target = tmp_path / f"x.{ext}"
    with full_disk(3000), pytest.raises(SplatglError) as info:
        write_image(target, _image())
    message = str(info.value)
    assert message.startswith(f"{target}: cannot write") and "partial" not in message, message
    assert "\n" not in message
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("ext", ["png", "tif", "exr"])
def test_image_file_problem_finds_cut_and_other_files(tmp_path, ext):
    good = tmp_path / f"good.{ext}"
    write_image(good, _image())
    assert image_file_problem(good, 96, 64) is None
    assert image_file_problem(good, 64, 96) == "it is 96x64, not 64x96"
    data = good.read_bytes()
    for keep in (0, 100, len(data) // 2, len(data) - 1):
        cut = tmp_path / f"cut.{ext}"
        cut.write_bytes(data[:keep])
        problem = image_file_problem(cut, 96, 64)
        assert problem is not None and ("cut short" in problem or "empty" in problem
                                        or "not a readable image" in problem), (keep, problem)
    if ext != "exr":
        write_image(tmp_path / f"deep.{ext}", _image(), 16)
        assert image_file_problem(tmp_path / f"deep.{ext}", 96, 64, 3, 8) == \
            "it has 16 bits per channel, not 8"


def test_render_to_a_full_disk_fails_in_one_line(tmp_path, capsys, full_disk):
    out = tmp_path / "x.png"
    with full_disk(3000):
        code = main(["render", str(demo_scene_path()), *SIZE, "-o", str(out)])
    assert code == 2
    err = _one_line(capsys)
    assert err.startswith(f"splatgl: error: {out}: cannot write: the file is cut short"), err
    assert "wrote" not in capsys.readouterr().out and list(tmp_path.iterdir()) == []
