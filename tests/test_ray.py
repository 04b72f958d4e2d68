"""``--executor ray``: a camera path as Ray tasks on a local Ray started by the test (2 CPUs)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

from splatgl.cli import main
from splatgl.distributed import ray_executor

ray = pytest.importorskip("ray", reason="Ray is not installed (pip install 'splatgl[ray]')")

ARGS = ["--path", "orbit:16", "--width", "96", "--height", "72"]


@pytest.fixture(scope="module")
def local_ray(tmp_path_factory):
    """A local Ray of 2 CPUs; tasks see the kill-once marker path (absent until a test removes
    it, so the other tests run without a kill)."""
    marker = tmp_path_factory.mktemp("ray") / "killed-once"
    marker.write_text("armed later\n")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, logging_level="ERROR",
             runtime_env={"env_vars": {ray_executor.KILL_ONCE_ENV: str(marker)}})
    yield marker
    ray.shutdown()


def _files(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


@pytest.fixture(scope="module")
def single_process(tmp_path_factory):
    out = tmp_path_factory.mktemp("one") / "frames"
    assert main(["render", *ARGS, "-o", f"{out}/"]) == 0
    return _files(out)


def test_ray_frames_equal_the_single_process_render(local_ray, single_process, tmp_path):
    out = tmp_path / "frames"
    assert main(["render", *ARGS, "-o", f"{out}/", "--executor", "ray"]) == 0
    got = _files(out)
    assert len(got) == 16 and got == single_process


def test_killed_worker_is_retried(local_ray, single_process, tmp_path):
    local_ray.unlink()                 # the next task to start kills its worker once
    out = tmp_path / "frames"
    assert main(["render", *ARGS, "-o", f"{out}/", "--executor", "ray"]) == 0
    assert local_ray.read_text() == "killed once\n"          # a worker did die ...
    assert _files(out) == single_process                      # ... and its chunk was redone
    assert not [p for p in out.iterdir() if ".partial" in p.name or p.name.startswith(".")]


def test_resume_renders_only_missing_frames(local_ray, single_process, tmp_path, capsys):
    out = tmp_path / "frames"
    assert main(["render", *ARGS, "-o", f"{out}/", "--executor", "ray"]) == 0
    for name in ("00003.png", "00011.png"):
        (out / name).unlink()
    capsys.readouterr()
    assert main(["render", *ARGS, "-o", f"{out}/", "--executor", "ray", "--resume"]) == 0
    out_text = capsys.readouterr().out
    assert "wrote 2 frames" in out_text and "14 already there" in out_text
    assert _files(out) == single_process


def test_missing_ray_gives_the_install_hint(monkeypatch, tmp_path, capsys):
    monkeypatch.setitem(sys.modules, "ray", None)      # import ray -> ImportError
    assert main(["render", *ARGS, "-o", f"{tmp_path}/f/", "--executor", "ray"]) == 2
    assert capsys.readouterr().err.strip() == (
        "splatgl: error: --executor ray needs Ray: pip install 'splatgl[ray]'")
    assert not (tmp_path / "f").exists()


def test_ray_refuses_video_and_workers(tmp_path, capsys):
    assert main(["render", *ARGS, "-o", str(tmp_path / "v.mp4"), "--executor", "ray"]) == 2
    assert "--executor ray renders image frames" in capsys.readouterr().err
    assert main(["render", *ARGS, "-o", f"{tmp_path}/f/", "--executor", "ray", "--workers", "2"]) == 2
    assert "--workers is for --executor local" in capsys.readouterr().err
    assert not os.listdir(tmp_path)
