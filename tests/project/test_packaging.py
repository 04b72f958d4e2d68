"""A non-editable wheel install finds every shader and the demo scene, and renders."""

from __future__ import annotations

import os
import subprocess
import sys
import venv
from pathlib import Path

import pytest

from helpers import REPO

pytestmark = [pytest.mark.wheel, pytest.mark.slow]


def test_wheel_install_renders(tmp_path):
    dist = tmp_path / "dist"
    build = subprocess.run(
        [sys.executable, "-m", "build", "--wheel", "--no-isolation", "--outdir", str(dist), str(REPO)],
        capture_output=True, text=True)
    if build.returncode != 0 and "No module named build" in build.stderr:
        pytest.skip("the 'build' package is not installed (pip install '.[test]')")
    assert build.returncode == 0, build.stdout[-2000:] + build.stderr[-2000:]
    wheels = list(dist.glob("splatgl-*.whl"))
    assert len(wheels) == 1

    # A venv that sees the test environment's packages (moderngl, numpy, ...) through a plain
    # path line in a .pth file, which does not run that environment's own .pth files, so an
    # editable splatgl there stays invisible; splatgl comes only from the wheel.
    env_dir = tmp_path / "venv"
    venv.create(env_dir, with_pip=False)
    py = env_dir / "bin" / "python"
    site = subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                          capture_output=True, text=True, check=True).stdout.strip()
    here = [p for p in sys.path if p.endswith("site-packages")]
    (Path(site) / "_test_env.pth").write_text("\n".join(here) + "\n")
    subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "--quiet", "--target", site,
                    str(wheels[0])], check=True)

    work = tmp_path / "elsewhere"  # not the repository: nothing may come from the source tree
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    code = (
        "import splatgl, pathlib, sys\n"
        "from splatgl.gl.shaders import shader_dir\n"
        "from splatgl.cli import main\n"
        "print(splatgl.__file__)\n"
        "print(shader_dir())\n"
        "sys.exit(main(['render', '-o', 'demo.png', '--width', '64', '--height', '36']))\n"
    )
    run = subprocess.run([str(py), "-c", code], cwd=work, capture_output=True, text=True, env=env)
    assert run.returncode == 0, run.stdout + run.stderr
    module_file, shaders = run.stdout.splitlines()[:2]
    assert module_file.startswith(site), module_file
    assert shaders.startswith(site), shaders
    shipped = {p.relative_to(shaders).as_posix() for p in Path(shaders).rglob("*") if p.is_file()}
    in_repo = {p.relative_to(REPO / "shaders").as_posix() for p in (REPO / "shaders").rglob("*") if p.is_file()}
    assert in_repo <= shipped, f"shaders missing from the wheel: {sorted(in_repo - shipped)}"
    assert (work / "demo.png").stat().st_size > 100
