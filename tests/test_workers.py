"""``--workers N``: local processes on contiguous chunks give the same files as one process."""

from __future__ import annotations

import numpy as np

from splatgl.cli import main
from splatgl.commands._common import demo_scene_path
from splatgl.image_io import read_image
from splatgl.workers import chunks


def test_chunks_are_contiguous_and_cover():
    assert chunks(10, 3) == [range(0, 3), range(3, 7), range(7, 10)]
    assert chunks(2, 4) == [range(0, 1), range(1, 2)]
    assert [i for c in chunks(17, 5) for i in c] == list(range(17))


def test_two_workers_write_the_single_process_files(tmp_path, capsys):
    args = ["render", str(demo_scene_path()), "--path", "orbit:5", "--width", "96", "--height", "64"]
    assert main([*args, "-o", str(tmp_path / "one")]) == 0
    assert main([*args, "-o", str(tmp_path / "two"), "--workers", "2"]) == 0
    assert "wrote 5 frames" in capsys.readouterr().out
    assert sorted(p.name for p in (tmp_path / "two").iterdir()) == [f"{k:05d}.png" for k in range(5)]
    for k in range(5):
        np.testing.assert_array_equal(read_image(tmp_path / "one" / f"{k:05d}.png"),
                                      read_image(tmp_path / "two" / f"{k:05d}.png"))
    (tmp_path / "two" / "00003.png").unlink()
    assert main([*args, "-o", str(tmp_path / "two"), "--workers", "2", "--resume"]) == 0
    assert "wrote 1 frames" in capsys.readouterr().out


def test_workers_refuse_video(tmp_path, capsys):
    assert main(["render", "--path", "orbit:2", "--workers", "2", "-o", str(tmp_path / "v.mp4")]) == 2
    assert "--workers renders image frames; write a video with one process" in capsys.readouterr().err
