"""Numerical stress cases (splatgl.measure.stress): every renderer finite, within its bound, no hang.

Each case renders with the quad path, the tile renderer, the CPU renderer (with numba) and the
float32 reference and is compared with the float64 reference; the bounds and their derivation live with the cases
(splatgl/measure/stress/cases.py).  A watchdog exits the run if a case hangs.  The 8192 x 8192 case
(~40 s, ~10 GB) runs only with SPLATGL_STRESS_SLOW=1.
"""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from splatgl.cli import main
from splatgl.measure.stress import CASES, FIXES, case_by_name, run_case
from splatgl.measure.stress.run import watchdog

#: Per-case hang limit in the tests (every fast case takes well under a second).
CASE_HANG_S = 120.0
#: Ceiling for the errors of known, unfixed failures (the worst measured is 0.335).
KNOWN_FAILURE_LIMIT = 0.4


def _check(result) -> None:
    known = []
    for row in result.rows:
        assert row.status != "error", f"{result.case}/{row.renderer} crashed: {row.message}"
        if row.status == "unsupported":
            continue
        assert row.finite, f"{result.case}/{row.renderer}: NaN or Inf in the output"
        if row.status == "known":
            # A known, documented failure still may not get worse than measured (0.335 for
            # the RGBA16F 10k-layer case): the bound below catches a regression.
            assert row.max_error < KNOWN_FAILURE_LIMIT, f"{result.case}/{row.renderer}: {row.message}"
            known.append(f"{row.renderer}: {row.message}")
            continue
        assert row.status == "ok", f"{result.case}/{row.renderer}: {row.message}"
    if known:
        pytest.xfail("; ".join(known))


@pytest.mark.parametrize("name", [c.name for c in CASES if not c.slow])
def test_stress_case(gl_renderer, name):
    with watchdog(CASE_HANG_S):
        _check(run_case(case_by_name(name), gl_renderer))


@pytest.mark.skipif(os.environ.get("SPLATGL_STRESS_SLOW") != "1",
                    reason="8192 x 8192 case: ~40 s and ~10 GB; set SPLATGL_STRESS_SLOW=1")
@pytest.mark.parametrize("name", [c.name for c in CASES if c.slow])
def test_stress_case_slow(gl_renderer, name):
    with watchdog(600.0):
        _check(run_case(case_by_name(name), gl_renderer))


def test_zero_quaternions_never_nan():
    """The defined behaviour of a degenerate quaternion: identity rotation, opacity 0."""
    scene = case_by_name("zero_quats").build().scene
    assert np.isfinite(scene.rotations).all()
    assert (scene.opacities[[1, 3, 4]] == 0.0).all() and (scene.opacities[[0, 2]] > 0.5).all()


def test_anchor_keeps_far_scenes_small():
    scene = case_by_name("far_1e7").build().scene
    assert np.abs(scene.anchor).max() > 1e6
    assert np.abs(scene.relative_means).max() <= 3.0


def test_every_fix_names_its_place_and_failure():
    assert FIXES
    for fix in FIXES:
        assert fix.title and fix.where and fix.before


def test_cli_table_and_fixes(capsys):
    assert main(["stress", "--case", "image_1x1", "--case", "zero_quats"]) == 0
    out = capsys.readouterr().out
    for text in ("case", "renderer", "finite", "max error", "bound", "seconds", "reference64",
                 "quad", "tile", "reference32", "image_1x1", "zero_quats", "fixes", "before:"):
        assert text in out


def test_cli_json(capsys):
    assert main(["stress", "--case", "near_plane", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    rows = data["cases"][0]["rows"]
    assert [r["renderer"] for r in rows] == ["reference64", "quad", "tile", "cpu", "reference32"]
    assert all(r["finite"] for r in rows) and data["fixes"]


def test_without_numba_the_cpu_row_is_left_out_and_asking_for_it_names_the_extra(capsys,
                                                                                 monkeypatch):
    from splatgl.scene.settings import RendererKind
    from splatgl.renderers import registry

    monkeypatch.setattr(registry, "installed", lambda kind: RendererKind(kind) is not RendererKind.CPU)
    assert main(["stress", "--case", "image_1x1", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)["cases"][0]["rows"]
    assert [r["renderer"] for r in rows] == ["reference64", "quad", "tile", "reference32"]
    assert main(["stress", "--case", "image_1x1", "--renderer", "cpu"]) == 2
    err = capsys.readouterr().err
    assert "pip install 'splatgl[fast]'" in err and len(err.strip().splitlines()) == 1, err


def test_cli_unknown_case(capsys):
    assert main(["stress", "--case", "no_such_case"]) == 2
    assert "no_such_case" in capsys.readouterr().err
