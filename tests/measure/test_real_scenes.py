"""The benchmark's large scenes from real data (splatgl/measure/bench/real_scenes.py)."""

from __future__ import annotations

import numpy as np
import pytest

from splatgl.measure.bench.real_scenes import build_real_scene, load_real_sources
from splatgl.errors import SplatglError
from splatgl.splatmath.project import covariance_3d, quat_to_rotmat
from splatgl.scene.splats import Scene


def _source(n: int, seed: int, degree: int = 0) -> Scene:
    rng = np.random.default_rng(seed)
    return Scene(rng.normal(size=(n, 3)) * [3.0, 1.0, 2.0] + [10.0, -2.0, 5.0],
                 rng.normal(size=(n, 4)), rng.normal(-3.0, 0.5, (n, 3)), rng.normal(0, 2, n),
                 rng.normal(0, 0.3, (n, (degree + 1) ** 2, 3)))


@pytest.mark.parametrize("n", [1, 999, 1000, 2500])
def test_exact_count_and_deterministic(n):
    sources = [_source(1000, 1), _source(700, 2, degree=1)]
    a = build_real_scene(n, seed=3, sources=sources)
    b = build_real_scene(n, seed=3, sources=sources)
    assert a.count == n and a.sh_degree == 1
    for name in ("means", "quats", "log_scales", "opacity_logits", "sh"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    if n > 1:
        c = build_real_scene(n, seed=4, sources=sources)
        assert not np.array_equal(a.means, c.means)


def test_copy_is_a_rigid_similarity_of_its_source():
    """Without jitter noise the copy's covariances are R (f^2 Sigma) R^T of the source's:
    means and quaternions turn together.  Checked on the first (complete) copy with the
    per-splat jitter measured against its bound: positions move by 0.25 min-scale sigma."""
    src = _source(500, 5)
    out = build_real_scene(500, seed=0, sources=[src])
    # Recover the copy's similarity from the means (least squares), then compare covariances.
    a = src.means.astype(np.float64) - src.means.mean(axis=0)
    b = out.means.astype(np.float64) - out.means.mean(axis=0)
    u, s, vt = np.linalg.svd(a.T @ b)
    rot = (u @ vt).T
    factor = s.sum() / (a * a).sum()
    assert abs(rot[1, 1] - 1.0) < 1e-3  # a turn about the vertical axis only
    cov_src = covariance_3d(quat_to_rotmat(src.quats.astype(np.float64)), src.scales.astype(np.float64))
    cov_out = covariance_3d(quat_to_rotmat(out.quats.astype(np.float64)), out.scales.astype(np.float64))
    expect = factor ** 2 * np.einsum("ij,njk,lk->nil", rot, cov_src, rot)
    # Log-scale jitter 0.05 sigma: covariances agree to exp(2 * 4 * 0.05) ~ 1.5 at most.
    ratio = np.trace(cov_out, axis1=1, axis2=2) / np.trace(expect, axis1=1, axis2=2)
    assert 0.6 < ratio.min() and ratio.max() < 1.6
    assert abs(np.median(ratio) - 1.0) < 0.02
    np.testing.assert_array_equal(out.opacity_logits, src.opacity_logits)


def test_rejects_bad_count():
    with pytest.raises(SplatglError, match="at least 1 splat"):
        build_real_scene(0, sources=[_source(10, 0)])


def test_real_sources_build(shared_scenes):
    sources = load_real_sources(root=shared_scenes)
    scene = build_real_scene(400_000, seed=0, sources=sources)
    assert scene.count == 400_000
    assert np.isfinite(scene.means).all()
    # Copies keep their source's opacities (a real distribution, not a synthetic one).
    assert np.median(scene.opacities) == pytest.approx(
        np.median(np.concatenate([s.opacities for s in sources])), abs=0.05)


def test_shared_scenes_lookup_env_then_working_directory(tmp_path, monkeypatch):
    """One lookup for the bench and the tests: the variable, else ../shared/scenes from the
    working directory (never beside the installed package's files)."""
    from splatgl.measure.bench import real_scenes
    from splatgl.measure.bench.real_scenes import shared_scenes_dir

    work = tmp_path / "checkout"
    work.mkdir()
    # An installed package whose folder happens to have a shared/scenes three levels up: not used.
    site = tmp_path / "site"
    (site / "shared" / "scenes").mkdir(parents=True)
    monkeypatch.setattr(real_scenes, "__file__", str(site / "lib" / "splatgl" / "measure" / "bench" / "real_scenes.py"))
    monkeypatch.chdir(work)
    monkeypatch.delenv("SPLATGL_SHARED_SCENES", raising=False)
    assert shared_scenes_dir() == tmp_path / "shared" / "scenes"
    assert shared_scenes_dir(tmp_path / "a" / "repo") == tmp_path / "a" / "shared" / "scenes"
    monkeypatch.setenv("SPLATGL_SHARED_SCENES", str(tmp_path / "elsewhere"))
    assert shared_scenes_dir() == tmp_path / "elsewhere"
    assert shared_scenes_dir(tmp_path / "a" / "repo") == tmp_path / "elsewhere"


def test_missing_real_scene_names_folder_and_variable(tmp_path, monkeypatch):
    monkeypatch.setenv("SPLATGL_SHARED_SCENES", str(tmp_path))
    with pytest.raises(SplatglError, match=r"donut_sh0.ply: real scene not found \(set SPLATGL_SHARED_SCENES\)"):
        load_real_sources()


def test_bench_help_says_where_it_looks(tmp_path, monkeypatch, capsys):
    from splatgl.cli import main

    monkeypatch.setenv("SPLATGL_SHARED_SCENES", str(tmp_path / "scenes"))
    with pytest.raises(SystemExit):
        main(["bench", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "$SPLATGL_SHARED_SCENES if set, else ../shared/scenes from the working directory" in text
    assert f"(here: {tmp_path / 'scenes'})" in text
