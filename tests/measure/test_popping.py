"""The popping metric (splatgl/measure/evaluation/popping.py) on synthetic frames with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from splatgl.cameras.camera import Camera
from splatgl.cameras.poses import look_at
from splatgl.measure.evaluation.popping import (POP_THRESHOLD, Frame, distribution, flip_available,
                                        popping, score_pair)

W, H = 96, 64


def plane_frame(eye, target, planes=((5.0, None),)) -> Frame:
    """A frame of textured planes z = const (world), each limited to |x| < half (None: infinite);
    the nearest plane a pixel's ray meets is seen; its colour depends on the world point only."""
    cam = Camera.from_fov(W, H, 50.0, look_at(eye, target))
    j, i = np.meshgrid(np.arange(W) + 0.5, np.arange(H) + 0.5)
    d_cam = np.stack([(j - cam.cx) / cam.fx, (i - cam.cy) / cam.fy, np.ones_like(j)], -1)
    d_world = d_cam @ cam.rotation                        # R^T d, view z of d is 1
    centre = cam.center
    depth = np.full((H, W), np.inf)
    point = np.zeros((H, W, 3))
    for z_plane, half in planes:
        s = (z_plane - centre[2]) / d_world[..., 2]
        p = centre + s[..., None] * d_world
        hit = (s > 0) & (s < depth) & ((np.abs(p[..., 0]) < half) if half else True)
        depth = np.where(hit, s, depth)
        point = np.where(hit[..., None], p, point)
    rgb = np.stack([0.5 + 0.3 * np.sin(3 * point[..., 0]) * np.cos(2 * point[..., 1]),
                    0.5 + 0.2 * np.cos(point[..., 0] + point[..., 1]),
                    0.4 + 0.0 * point[..., 2]], -1)
    alpha = np.isfinite(depth).astype(float)
    return Frame(rgb, np.where(np.isfinite(depth), depth, 0.0), alpha, cam)


A = ([0.0, 0.0, 0.0], [0.0, 0.0, 5.0])
B = ([0.06, 0.02, 0.05], [0.02, 0.0, 5.0])


def test_motion_alone_does_not_pop():
    [pair] = popping([plane_frame(*A), plane_frame(*B)], "own")
    assert pair.popped == 0.0 and pair.score < 2e-3 and pair.kept > 0.9


def test_a_changed_square_pops_by_its_area():
    a, b = plane_frame(*A), plane_frame(*B)
    rgb = b.rgb.copy()
    rgb[20:30, 40:50] = [0.9, 0.1, 0.1]                   # a splat "popped" in front: 100 px
    pair, err = score_pair(a, Frame(rgb, b.depth, b.alpha, b.camera), 1, "own")
    kept = round(pair.kept * W * H)
    assert pair.popped == pytest.approx(100 / kept, abs=1e-12)
    assert pair.coherent == pytest.approx(64 / kept, abs=1e-12)      # the square's 8x8 inside
    assert (err[20:30, 40:50] > POP_THRESHOLD["own"]).all()


def test_speckle_is_popped_but_not_coherent():
    a, b = plane_frame(*A), plane_frame(*B)
    rgb = b.rgb.copy()
    rgb[10:50:4, 10:80:4] = [0.9, 0.1, 0.1]             # isolated pixels, 4 apart
    pair, _ = score_pair(a, Frame(rgb, b.depth, b.alpha, b.camera), 1, "own")
    assert pair.popped > 0.02 and pair.coherent == 0.0


def test_disocclusions_are_masked_not_counted():
    planes = ((3.0, 0.4), (6.0, None))                   # a strip in front of a wall
    a = plane_frame([0.0, 0.0, 0.0], [0.0, 0.0, 5.0], planes)
    b = plane_frame([0.25, 0.0, 0.0], [0.25, 0.0, 5.0], planes)
    [pair] = popping([a, b], "own")
    assert pair.popped == 0.0 and pair.kept < 0.95        # the wall behind the strip is masked


@pytest.mark.skipif(not flip_available(), reason="flip-evaluator is not installed (the fidelity extra)")
def test_flip_metric_sees_the_square():
    a, b = plane_frame(*A), plane_frame(*B)
    rgb = b.rgb.copy()
    rgb[20:30, 40:50] = [0.9, 0.1, 0.1]
    [still] = popping([a, b], "flip")
    pair, err = score_pair(a, Frame(rgb, b.depth, b.alpha, b.camera), 1, "flip")
    assert still.popped < 0.005
    popped_pixels = pair.popped * pair.kept * W * H
    assert 100 <= popped_pixels <= 300                    # FLIP's filters spread an edge by a few px
    assert (err[22:28, 42:48] > POP_THRESHOLD["flip"]).all()


def test_distribution():
    a, b, c = plane_frame(*A), plane_frame(*B), plane_frame(*A)
    d = distribution(popping([a, b, c], "own"))
    assert d["pairs"] == 2 and d["popped_max"] == 0.0 and d["score_p90"] < 2e-3


def test_bench_popping_cli(tmp_path, capsys):
    from splatgl.cli import main
    from splatgl.commands._common import demo_scene_path

    out = tmp_path / "pop"
    assert main(["bench", "--popping", str(demo_scene_path()), "--width", "48", "--height", "32",
                 "--frames", "3", "--popping-configs", "tile,tile per-pixel",
                 "--popping-metric", "own", "--out", str(out)]) == 0
    import json
    report = json.loads((out / "popping.json").read_text())
    rows = report["rows"]
    assert {(r["path"], r["config"]) for r in rows} == {
        (p, c) for p in ("orbit", "fly", "turn") for c in ("tile", "tile per-pixel")}
    assert all(r["pairs"] == 2 and r["metric"] == "own" for r in rows)
    assert all("still_psnr_vs_global" in r for r in rows if r["config"] == "tile per-pixel")
    assert "coh. max" in capsys.readouterr().out
    assert main(["bench", "--popping", "--popping-configs", "tile,fast"]) == 2
    assert "--popping-configs: unknown fast" in capsys.readouterr().err
    assert main(["bench", "--popping", "--scale"]) == 2
    assert "--popping runs alone" in capsys.readouterr().err


def _refused(capsys, tmp_path, argv, line):
    from splatgl.cli import main
    before = sorted(p.name for p in tmp_path.iterdir())
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert (rc, out, err) == (2, "", line + "\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_bench_popping_one_frame_is_one_line_before_work(tmp_path, capsys):
    """Issue 38: --frames 1 measured every scene, then raised KeyError (no pair to score)."""
    from splatgl.commands._common import demo_scene_path
    _refused(capsys, tmp_path, ["bench", "--popping", demo_scene_path(), "--frames", "1",
                                "--popping-metric", "own", "--out", tmp_path / "pop"],
             "splatgl: error: --frames 1: --popping scores pairs of consecutive frames, so a "
             "path needs at least 2")


def test_popping_options_refuse_what_measures_nothing():
    from splatgl.measure.bench.popping_bench import PoppingOptions
    from splatgl.errors import SplatglError
    with pytest.raises(SplatglError, match=r"^--frames 1: --popping scores pairs"):
        PoppingOptions(frames=1)
    with pytest.raises(SplatglError, match=r"^--popping-window must be 1..32, got 0$"):
        PoppingOptions(window=0)
    with pytest.raises(SplatglError, match=r"^--popping-configs: none given"):
        PoppingOptions(configs=())


def test_bench_popping_window_zero_is_refused(tmp_path, capsys):
    """--popping-window 0 was taken as the default window."""
    _refused(capsys, tmp_path, ["bench", "--popping", "--popping-window", "0"],
             "splatgl: error: --popping-window must be 1..32, got 0")
    _refused(capsys, tmp_path, ["bench", "--popping", "--popping-window", "8",
                                "--popping-configs", "quad,tile"],
             "splatgl: error: --popping-window 8: the window is the 'tile per-pixel' "
             "configuration's, which --popping-configs leaves out")
    _refused(capsys, tmp_path, ["bench", "--quick", "--popping-window", "8"],
             "splatgl: error: --popping-window: an option of the popping benchmark; add --popping")


def test_bench_interactive_and_popping_are_refused_together(tmp_path, capsys):
    """--interactive --popping ran only the popping benchmark."""
    _refused(capsys, tmp_path, ["bench", "--interactive", "--popping"],
             "splatgl: error: --popping runs alone in one process (not with --interactive, "
             "--scale, --lod, --workers, --executor ray or --json; --out DIR writes popping.json)")
    _refused(capsys, tmp_path, ["bench", "--interactive", "--scale"],
             "splatgl: error: --interactive and --scale are separate benchmarks: run one at a "
             "time (each writes its own JSON with --out DIR)")
