"""benchmarks/gpu_check.sh: the commands it runs, and its renderer check on this llvmpipe machine.

The full run needs an NVIDIA GPU (and is long); here: --dry-run's command list, bad usage, and
the first step for real (a software renderer stops the run with one clear line).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
SCRIPT = REPO / "benchmarks" / "gpu_check.sh"

pytestmark = pytest.mark.skipif(shutil.which("bash") is None or shutil.which("realpath") is None,
                                reason="needs bash and GNU realpath")


def _run(args, tmp_path, path_extra=None, **env):
    base = {k: v for k, v in os.environ.items()
            if k not in ("SPLATGL_GPU_CHECK_ALLOW_SOFTWARE", "SPLATGL_EGL_DEVICE",
                         "GLCONTEXT_DEVICE_INDEX", "SPLATGL_GL_BACKEND")}
    base.update({"PYTHON": sys.executable, "PYTHONPATH": str(REPO),
                 "SPLATGL_SHARED_SCENES": str(tmp_path), **env})
    if path_extra is not None:
        base["PATH"] = f"{path_extra}{os.pathsep}{base['PATH']}"
    return subprocess.run(["bash", str(SCRIPT), *args], capture_output=True, text=True, env=base,
                          cwd=tmp_path, timeout=120)


def test_dry_run_prints_every_step_and_writes_nothing(tmp_path):
    out = tmp_path / "results"
    r = _run(["--dry-run", str(out)], tmp_path)
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    py = f"{REPO / '.venv'}/bin/python"
    expected = [
        "+ nvidia-smi",
        f"+ {py} -m pip install '.[test,fast,bench]'",
        f"+ {py} -m splatgl.commands._bench_tools gpu-probe --out {out}/machine.json --commit",
        f"+ {py} -m pytest -ra --junitxml={out}/pytest.xml",
        f"+ {py} -m splatgl bench --out {out}/bench",
        f"+ {py} -m splatgl bench --groups early-stop --out {out}/early-stop",
        f"+ {py} -m splatgl bench --scale --sizes 3M,6M --sh3-sizes none --out {out}/scale/c",
        f"+ {py} -m splatgl bench --scale --sizes none --sh3-sizes 6M --width 1280 --height 720 "
        f"--out {out}/scale/d",
        f"+ {py} -m splatgl.commands._bench_tools scale-report {out}/scale/a/scale.json {out}/scale/b/scale.json "
        f"{out}/scale/c/scale.json {out}/scale/d/scale.json --out {out}/scale",
    ]
    at = 0
    for want in expected:  # in this order
        found = [i for i, line in enumerate(lines) if i >= at and line.startswith(want)]
        assert found, f"{want!r} not printed (after line {at}):\n{r.stdout}"
        at = found[0] + 1
    assert not out.exists()


def test_quick_dry_run_gathers_issue_40s_figures_from_wheels(tmp_path):
    """--quick (issue 40 item 6): installs from the wheelhouse with no package index, then the
    radix sort alone, the scenes, both renderers with both orders at both resolutions and the
    flights, each under the time guard; without OUT_DIR into docs/results/gpu-<device>-<date>."""
    wheels = tmp_path / "wheels"
    r = _run(["--dry-run", "--quick", "--wheelhouse", str(wheels)], tmp_path)
    assert r.returncode == 0, r.stderr
    probe = next(line for line in r.stdout.splitlines() if "gpu-probe" in line)
    out = str(Path(probe.split("--out ")[1].split()[0]).parent)
    assert Path(out).parent == REPO / "docs" / "results" and Path(out).name.startswith("gpu-")
    py = sys.executable
    expected = [
        f"+ {py} -m pip install -q --no-index --find-links {wheels} --no-deps",
        f"+ {py} -m splatgl.commands._bench_tools gpu-probe --out {out}/machine.json",
        f"{py} benchmarks/radix_sort.py --sizes 100k,1M,6M --repeats 5 --no-old --json {out}/radix.json",
        f"{py} benchmarks/gpu_figures.py scene 1M,6M --cache",
        f"{py} benchmarks/gpu_figures.py renderers /tmp/splatgl-gpu-scenes/SIZE.ply "
        f"--resolutions 1280x720,1920x1080 --frames 5 --out {out}/figures.jsonl --deadline",
        f"{py} -m splatgl bench --interactive {tmp_path}/ply/donut_sh0.ply --width 1280 --height 720 "
        f"--out {out}/flight-donut",
        f"--out {out}/flight-guitar",
        f"--out {out}/flight-large",
    ]
    at = 0
    for want in expected:  # in this order
        found = [i for i, line in enumerate(r.stdout.splitlines()) if i >= at and want in line]
        assert found, f"{want!r} not printed (after line {at}):\n{r.stdout}"
        at = found[0] + 1
    assert "timeout --kill-after=5" in r.stdout and "-m pytest" not in r.stdout
    assert not Path(out).exists()


def test_dry_run_steps_and_no_install(tmp_path):
    r = _run(["--dry-run", "--no-install", "--steps", "bench", str(tmp_path / "o")], tmp_path)
    assert r.returncode == 0, r.stderr
    assert "-m pip" not in r.stdout and "-m pytest" not in r.stdout and "--scale" not in r.stdout
    assert f"+ {sys.executable} -m splatgl bench --out {tmp_path}/o/bench" in r.stdout


@pytest.mark.parametrize("args, message", [
    (["--steps", "bench,lod", "o"], "--steps: unknown step 'lod' (steps: tests,bench,early-stop,scale)"),
    (["--frobnicate", "o"], "unknown option --frobnicate (see --help)"),
    ([], "no output folder (usage: benchmarks/gpu_check.sh [options] OUT_DIR)"),
    (["--quick", "--smoke", "o"], "--quick or --smoke, not both"),
    (["--wheelhouse", "w", "o"], "--wheelhouse goes with --quick"),
])
def test_bad_usage_is_one_line_exit_2(tmp_path, args, message):
    r = _run(args, tmp_path)
    assert r.returncode == 2 and r.stderr == f"gpu_check: error: {message}\n"


def test_software_renderer_stops_the_run(tmp_path):
    """With nvidia-smi present (a stub here) but EGL on llvmpipe, the renderer check fails:
    machine.json and machine.txt record the renderer, nothing else runs, exit 1."""
    from splatgl.errors import ContextError
    from splatgl.gl.context import create_headless_context
    from splatgl.gl.egl_devices import is_software_renderer

    try:
        ctx = create_headless_context()
    except ContextError as exc:
        pytest.skip(f"no OpenGL: {exc}")
    renderer = ctx.info["GL_RENDERER"]
    ctx.release()
    if not is_software_renderer(renderer):
        pytest.skip(f"this machine renders on hardware ({renderer})")
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    (bin_dir / "nvidia-smi").write_text("#!/bin/sh\necho 'NVIDIA stub, 1 GPU'\n")
    (bin_dir / "nvidia-smi").chmod(0o755)
    scenes = tmp_path / "scenes"
    for name in ("ply/donut_sh0.ply", "compressed_ply/biker.compressed.ply",
                 "compressed_ply/guitar.compressed.ply"):
        (scenes / name).parent.mkdir(parents=True, exist_ok=True)
        (scenes / name).write_bytes(b"")  # only their presence is checked before the renderer
    out = tmp_path / "results"
    r = _run(["--no-install", str(out)], tmp_path, path_extra=bin_dir,
             SPLATGL_SHARED_SCENES=str(scenes))
    assert r.returncode == 1
    assert r.stderr.splitlines()[-1] == (f"gpu_check: error: the GL renderer check failed (see "
                                         f"{out}/machine.txt); nothing else was run")
    assert "is a software rasteriser, not the GPU" in (out / "machine.txt").read_text()
    doc = json.loads((out / "machine.json").read_text())
    assert doc["gl"]["software"] is True and doc["machine"]["gl_renderer"].startswith(renderer)
    assert (out / "nvidia-smi.txt").read_text() == "NVIDIA stub, 1 GPU\n"
    summary = (out / "summary.txt").read_text()
    assert "renderer: FAILED (exit 1" in summary and "tests:" not in summary
    assert sorted(p.name for p in out.iterdir()) == ["machine.json", "machine.txt", "nvidia-smi.txt",
                                                     "summary.txt"]
    # The same folder again: refused (results are never mixed), before any work.
    r = _run(["--no-install", str(out)], tmp_path, path_extra=bin_dir, SPLATGL_SHARED_SCENES=str(scenes))
    assert r.returncode == 2 and "already holds results" in r.stderr


@pytest.mark.skipif(shutil.which("nvidia-smi") is not None, reason="this machine has nvidia-smi")
def test_without_nvidia_smi_it_says_so(tmp_path):
    r = _run(["--no-install", str(tmp_path / "o")], tmp_path)
    assert r.returncode == 1
    assert r.stderr.startswith("gpu_check: error: nvidia-smi not found: this check is for a machine "
                               "with an NVIDIA GPU")
    assert not (tmp_path / "o").exists()


def test_gpu_probe_in_process(tmp_path, monkeypatch, capsys):
    """The probe on this machine's context: the JSON and the printed renderer agree; a bad
    SPLATGL_EGL_DEVICE is one line and exit 2 (no JSON)."""
    from splatgl.commands._bench_tools import gpu_probe_main
    from splatgl.errors import ContextError
    from splatgl.gl.context import create_headless_context, renderer_name

    for name in ("SPLATGL_EGL_DEVICE", "GLCONTEXT_DEVICE_INDEX", "SPLATGL_GL_BACKEND"):
        monkeypatch.delenv(name, raising=False)
    try:
        ctx = create_headless_context()
    except ContextError as exc:
        pytest.skip(f"no OpenGL: {exc}")
    name, raw = renderer_name(ctx), ctx.info["GL_RENDERER"]
    ctx.release()
    out = tmp_path / "machine.json"
    rc = gpu_probe_main(["--out", str(out), "--commit", "abc", "--allow-software"])
    assert rc == 0
    doc = json.loads(out.read_text())
    assert doc["machine"]["gl_renderer"] == name and doc["gl"]["renderer"] == raw
    assert doc["commit"] == "abc" and doc["gl"]["version_code"] >= 430
    assert f"GL renderer: {raw}\n" in capsys.readouterr().out
    monkeypatch.setenv("SPLATGL_EGL_DEVICE", "99")
    assert gpu_probe_main(["--out", str(tmp_path / "bad.json")]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and "SPLATGL_EGL_DEVICE=99: no such EGL device" in err
    assert not (tmp_path / "bad.json").exists()
