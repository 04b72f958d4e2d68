"""``render --path --preview`` and ``bench --interactive`` end to end: the CLI, its refusals, and
the flight benchmark's figures on a fast, short flight."""

from __future__ import annotations

import json

import numpy as np
import pytest

from splatgl.cli import main
from splatgl.imagefiles.images import read_image


def _run(capsys, *argv) -> tuple[int, str, str]:
    code = main(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


def test_preview_writes_draft_frames_and_says_so(tmp_path, capsys):
    out = tmp_path / "frames"
    code, text, err = _run(capsys, "render", "--path", "orbit:3", "--preview", "--target-fps", "5000",
                           "--width", "160", "--height", "120", "-o", str(out))
    assert code == 0, err
    files = sorted(out.glob("*.png"))
    assert [f.name for f in files] == ["00000.png", "00001.png", "00002.png"]
    assert read_image(files[0]).shape == (120, 160, 3)          # upscaled to the path's size
    assert "draft frames, not the exact render" in text and "of 3 frames" in text
    assert "scale" in text                                       # a budget this tight draws drafts
    exact = tmp_path / "exact"
    assert _run(capsys, "render", "--path", "orbit:3", "--width", "160", "--height", "120",
                "-o", str(exact))[0] == 0
    assert not np.array_equal(read_image(files[1]), read_image(exact / "00001.png"))


@pytest.mark.parametrize("extra, message", [
    (["--resume"], "--resume would mix them"),
    (["--workers", "2"], "one process"),
    (["--renderer", "tile"], "quad path"),
    (["--target-fps", "0"], "must be positive"),
    (["--stereo", "0.06"], "--stereo cannot be combined"),
])
def test_preview_refusals(tmp_path, capsys, extra, message):
    code, _, err = _run(capsys, "render", "--path", "orbit:2", "--preview", *extra,
                        "-o", str(tmp_path / "f"))
    assert code == 2 and message in err and err.count("\n") == 1
    assert not (tmp_path / "f").exists()


def test_preview_refuses_depth_layers_and_target_fps_needs_preview(tmp_path, capsys):
    pattern = tmp_path / "f" / "%05d.exr"
    code, _, err = _run(capsys, "render", "--path", "orbit:2", "--preview", "-o", str(pattern))
    assert code == 2 and err == (f"splatgl: error: {pattern}: EXR frames carry Z (the depth layer), "
                                 "which --preview does not draw; give --layers colour,alpha for EXR "
                                 "drafts without Z, or use a .png pattern, a folder or a video\n")
    code, _, err = _run(capsys, "render", "--path", "orbit:2", "--preview", "--layers",
                        "colour,normal,depth", "-o", str(tmp_path / "f"))
    assert code == 2 and err == ("splatgl: error: --preview draws colour and alpha only, not "
                                 "--layers depth, normal (render the path without --preview for "
                                 "them)\n")
    assert not (tmp_path / "f").exists()
    code, _, err = _run(capsys, "render", "--path", "orbit:2", "--target-fps", "5",
                        "-o", str(tmp_path / "g"))
    assert code == 2 and "budget of --preview" in err


def test_preview_writes_the_alpha_layer_it_draws(tmp_path, capsys):
    """--layers alpha: each draft frame gets its alpha picture (it was dropped), and an EXR
    pattern with --layers colour,alpha holds R, G, B, A (no Z: asked without it)."""
    import OpenImageIO as oiio

    size = ["--width", "64", "--height", "48", "--target-fps", "5000"]
    code, _, err = _run(capsys, "render", "--path", "orbit:2", "--preview", "--layers", "alpha",
                        *size, "-o", str(tmp_path / "p") + "/")
    assert code == 0, err
    assert sorted(f.name for f in (tmp_path / "p").iterdir()) == [
        "00000.png", "00000_alpha.png", "00001.png", "00001_alpha.png"]
    code, _, err = _run(capsys, "render", "--path", "orbit:2", "--preview", "--layers",
                        "colour,alpha", *size, "-o", str(tmp_path / "e" / "%03d.exr"))
    assert code == 0, err
    inp = oiio.ImageInput.open(str(tmp_path / "e" / "001.exr"))
    assert tuple(inp.spec().channelnames) == ("R", "G", "B", "A")
    inp.close()


def test_bench_interactive_refuses_no_budget(capsys):
    code, _, err = _run(capsys, "bench", "--interactive", "--target-fps", "0")
    assert code == 2 and "must be positive" in err


def test_flight_figures_on_a_fast_flight(gl_renderer, tmp_path):
    from splatgl.measure.bench.flight import MAX_SCORED, fly
    from splatgl.measure.bench.flight_report import plot, table, write_json
    from splatgl.commands._common import demo_scene_path
    from splatgl.formats import load_scene

    scene = load_scene(demo_scene_path())
    # speed 4: the moving part lasts 2 s of wall time, room for 3 frames on a slow, busy machine
    result = fly(gl_renderer, scene, "demo", 160, 120, 50.0, speed=4.0, log=lambda m: None)
    s = result.summary()
    assert s["frames"] >= 3 and s["fps_median"] > 0
    assert result.exact_matches_render                        # the rest frame is render's
    assert s["rest_to_exact"] >= 0 and len(result.latencies) == 8
    scored = [f for f in result.frames if f.psnr is not None]   # evenly spread, at most MAX_SCORED
    assert len(scored) == min(len(result.frames), MAX_SCORED) or len(result.frames) > MAX_SCORED
    assert len(scored) >= min(len(result.frames), MAX_SCORED // 2) and result.frames[0].psnr is not None
    assert "demo" in table([result])
    write_json(tmp_path / "i.json", [result], {"machine": "test"})
    doc = json.loads((tmp_path / "i.json").read_text())
    assert doc["summary"][0]["frames"] == s["frames"]
    plot(tmp_path / "i.png", [result])
    assert (tmp_path / "i.png").stat().st_size > 1000


def test_flight_with_the_cpu_renderers_exact_frame(gl_renderer):
    """``bench --interactive --exact cpu``: the rest ends at the CPU renderer's frame (render's
    with kind cpu), and the moving frames are scored against it."""
    pytest.importorskip("numba", reason="the CPU renderer needs numba (the fast extra)")
    from splatgl.measure.bench.flight import fly
    from splatgl.commands._common import demo_scene_path
    from splatgl.formats import load_scene
    from splatgl.interactive.budget import EXACT

    scene = load_scene(demo_scene_path())
    result = fly(gl_renderer, scene, "demo", 160, 120, 50.0, speed=20.0, log=lambda m: None,
                 exact_kind="cpu")
    assert result.exact_matches_render and result.refine_steps[-1] == EXACT.describe()
    assert any(f.psnr is not None for f in result.frames)


def test_bench_exact_needs_interactive(capsys):
    code, _, err = _run(capsys, "bench", "--exact", "cpu")
    assert code == 2 and "add --interactive" in err


def test_view_errors_have_the_prefix_of_every_command(tmp_path, capsys):
    """A bad argument and a bad file say ``splatgl: error:`` alike (the argument error said
    ``splatgl view: error:``), both before any window opens."""
    code, out, err = _run(capsys, "view", "--target-fps", "fast")
    assert code == 2 and err.startswith("splatgl: error: argument --target-fps: ")
    assert err.endswith(" (see splatgl view --help)\n") and len(err.splitlines()) == 1
    code, out, err = _run(capsys, "view", str(tmp_path / "missing.ply"))
    assert code == 2 and err.startswith("splatgl: error: ") and len(err.splitlines()) == 1


def test_target_fps_is_one_option_in_every_command():
    """view, render --path --preview and bench --interactive add --target-fps through one helper
    (commands/_frame_budget.py): the same parsing and the default the library uses."""
    from splatgl.cli import build_parser
    from splatgl.interactive.session import GPU_FPS, SOFTWARE_FPS

    parser = build_parser()
    subs = next(a for a in parser._actions if hasattr(a, "choices") and isinstance(a.choices, dict))
    default = (f"(default: {SOFTWARE_FPS:g} on software OpenGL such as llvmpipe, {GPU_FPS:g} on "
               "a GPU")
    for command in ("view", "render", "bench"):
        action = next(a for a in subs.choices[command]._actions if "--target-fps" in a.option_strings)
        assert (action.type, action.default, action.metavar) == (float, None, "F")
        assert default in " ".join(action.help.split()), command
