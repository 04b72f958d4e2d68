"""``--executor ray``: a camera path as Ray tasks on a local Ray started by the test (2 CPUs)."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import numpy as np
import pytest

from splatgl.cli import main
from helpers import summary_counts
from splatgl.commands._common import demo_scene_path
from test_eval import N_VIEWS, dataset  # noqa: F401 (the module's fixture: a synthetic dataset)
from splatgl.tasks.task import KILL_ONCE_ENV

ray = pytest.importorskip("ray", reason="Ray is not installed (pip install 'splatgl[ray]')")

pytestmark = [pytest.mark.ray, pytest.mark.slow]

ARGS = ["--path", "orbit:16", "--width", "96", "--height", "72"]


@pytest.fixture(scope="module")
def local_ray(tmp_path_factory):
    """A local Ray of 2 CPUs; tasks see the kill-once marker path (absent until a test removes
    it, so the other tests run without a kill)."""
    marker = tmp_path_factory.mktemp("ray") / "killed-once"
    marker.write_text("armed later\n")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, logging_level="ERROR",
             runtime_env={"env_vars": {KILL_ONCE_ENV: str(marker)}})
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


def test_ray_refuses_workers(tmp_path, capsys):
    assert main(["render", *ARGS, "-o", f"{tmp_path}/f/", "--executor", "ray", "--workers", "2"]) == 2
    assert "--workers is for --executor local" in capsys.readouterr().err
    assert not os.listdir(tmp_path)


def test_ray_video_equals_the_single_process_video(local_ray, tmp_path, capsys):
    """16 frames as one Ray task (chunks of up to 32), encoded here: the same decoded frames as
    a single-process video; the summary names the node's IP."""
    pytest.importorskip("av", reason="PyAV is not installed (pip install 'splatgl[video]')")
    from splatgl.imagefiles.video import read_video_frames

    assert main(["render", *ARGS, "-o", str(tmp_path / "one.mp4")]) == 0
    capsys.readouterr()
    assert main(["render", *ARGS, "-o", str(tmp_path / "ray.mp4"), "--executor", "ray"]) == 0
    out = capsys.readouterr().out
    one, got = read_video_frames(tmp_path / "one.mp4"), read_video_frames(tmp_path / "ray.mp4")
    assert len(got) == 16 and all(np.array_equal(a, b) for a, b in zip(one, got))
    assert sorted(os.listdir(tmp_path)) == ["one.mp4", "ray.mp4"]
    workers, total = summary_counts(out, "frames")
    assert sum(workers) == total == 16
    ip = ray.util.get_node_ip_address()
    assert all(ip in line for line in out.splitlines() if line.startswith("worker "))


def test_ray_eval_equals_one_process(local_ray, dataset, tmp_path, capsys):
    """A dataset's views as Ray tasks: the same CSV as one process, every view counted once."""
    argv = ["eval", str(demo_scene_path()), "--dataset", str(dataset), "--background", "0.5,0.5,0.5"]
    assert main([*argv, "--csv", str(tmp_path / "one.csv")]) == 0
    capsys.readouterr()
    assert main([*argv, "--csv", str(tmp_path / "ray.csv"), "--executor", "ray"]) == 0
    assert (tmp_path / "ray.csv").read_text() == (tmp_path / "one.csv").read_text()
    workers, total = summary_counts(capsys.readouterr().out, "views")
    assert sum(workers) == total == N_VIEWS


def test_ray_bench_one_task_per_scene(local_ray, tmp_path, capsys):
    """Two scenes, two Ray tasks: the rows of both, in scene order, with the same accuracy
    columns as one process (timings differ run to run; the renders do not)."""
    argv = ["bench", str(demo_scene_path()), "--synthetic", "2000", "--quick", "--frames", "2",
            "--width", "64", "--height", "48", "--json"]
    assert main(argv) == 0
    one = json.loads(capsys.readouterr().out)
    assert main([*argv, "--executor", "ray"]) == 0
    out = capsys.readouterr().out
    got = json.loads(out.splitlines()[0])
    keys = ("scene", "config", "splats", "drawn", "fragments_shaded", "psnr", "max_abs")
    assert [[r[k] for k in keys] for r in got["rows"]] == [[r[k] for k in keys] for r in one["rows"]]
    assert [w["scene"] for w in got["workers"]] == ["demo.ply", "synthetic-2k-sh3"]
    assert sum(w["rows"] for w in got["workers"]) == len(got["rows"])


def test_ray_gpus_that_no_node_has_are_refused(local_ray, tmp_path, capsys):
    """`--ray-gpus 1` on a machine without a GPU queued every task forever, silently."""
    assert main(["render", *ARGS, "-o", f"{tmp_path / 'f'}/", "--executor", "ray", "--ray-gpus", "1"]) == 2
    err = capsys.readouterr().err
    assert err == ("splatgl: error: --ray-gpus 1: no node of the Ray cluster has 1 GPU (at most 0 "
                   "on one of its 1 node), so no task could ever start; use --ray-gpus 0 (the "
                   "default) or a cluster with GPUs\n")
    assert not (tmp_path / "f").exists() or list((tmp_path / "f").iterdir()) == []


def test_ray_renders_a_path_through_the_lod_cut(local_ray, tmp_path, capsys):
    """--lod-budget applies in Ray tasks too: the frames of one process, not full detail."""
    lod = tmp_path / "demo.lod.ply"
    assert main(["lod", str(demo_scene_path()), "-o", str(lod)]) == 0
    args = ["render", str(lod), "--path", "orbit:3", "--width", "96", "--height", "64"]
    assert main([*args, "--lod-budget", "300", "-o", f"{tmp_path / 'one'}/"]) == 0
    assert main([*args, "--lod-budget", "300", "-o", f"{tmp_path / 'ray'}/", "--executor", "ray"]) == 0
    assert main([*args, "-o", f"{tmp_path / 'full'}/"]) == 0
    one = _files(tmp_path / "one")
    assert len(one) == 3 and _files(tmp_path / "ray") == one
    assert all(one[name] != full for name, full in _files(tmp_path / "full").items())
