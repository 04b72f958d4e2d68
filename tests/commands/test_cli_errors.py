"""Bad arguments and bad camera files through the CLI: one exact line on stderr, exit 2, no file.

Each case is a command a user typed in the trial of issue 17; the expected line is the whole
message, so a reworded or multi-line error fails here.
"""

from __future__ import annotations

import json
import os
import re
import warnings

import numpy as np
import pytest

from splatgl.cameras.poses import look_at
from splatgl.cli import main


def run_cli(capsys, *argv):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a numpy cast warning must never be the only sign
        rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def expect_one_line(capsys, tmp_path, argv, line):
    """``argv`` exits 2 with exactly ``line`` on stderr and leaves tmp_path as it was."""
    before = sorted(p.name for p in tmp_path.iterdir())
    rc, out, err = run_cli(capsys, *argv)
    assert (rc, err) == (2, line + "\n"), err
    assert "Traceback" not in err and out == ""
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # nothing written or left


def camera_file(tmp_path, name="cam.json", width=64, height=48, w2c=None):
    w2c = look_at([0.0, -0.5, -3.0], [0.0, 0.0, 0.0]) if w2c is None else w2c
    path = tmp_path / name
    path.write_text(json.dumps({"width": width, "height": height, "fx": 60.0, "fy": 60.0,
                                "cx": width / 2, "cy": height / 2,
                                "world_to_camera": np.asarray(w2c).tolist()}))
    return path


R = "splatgl: error: argument "
HINT = " (see splatgl render --help)"


@pytest.mark.parametrize("extra, line", [
    (["--background", "nan,0,0"],
     R + "--background: each of R,G,B must be a finite number >= 0, got 'nan,0,0'" + HINT),
    (["--background", "1e400,0,0"],
     R + "--background: each of R,G,B must be a finite number >= 0, got '1e400,0,0'" + HINT),
    (["--near", "inf"], R + "--near: must be a finite number > 0, got 'inf'" + HINT),
    (["--near", "nan"], R + "--near: must be a finite number > 0, got 'nan'" + HINT),
    (["--camera-index", "-1"], R + "--camera-index: must be 0 or more, got -1" + HINT),
    (["--width", "0"], R + "--width: must be at least 1, got 0" + HINT),
    (["--distance", "-2"], R + "--distance: must be a finite number > 0, got '-2'" + HINT),
    (["--up", "x"], R + "--up: invalid choice: 'x' (choose from '+y', '-y', '+z', '-z')" + HINT),
    (["--camera-index", "2"], "splatgl: error: --camera-index needs --camera (a cameras.json to pick from)"),
    (["--width", "20000"], "splatgl: error: --width/--height: image 20000x720 is larger than "
                           "splatgl renders (16384 pixels a side)"),
    (["--convention", "gsplat"], "splatgl: error: --convention gsplat applies to the NumPy "
                                 "reference only; the quad renderer follows the inria rules "
                                 "(use --renderer reference)"),
    (["--convention", "gsplat", "--renderer", "tile"],
     "splatgl: error: --convention gsplat applies to the NumPy reference only; the tile renderer "
     "follows the inria rules (use --renderer reference)"),
    (["--transform", '{"rotate_deg": [0, 90, 0], "rotation": [[1,0,0],[0,1,0],[0,0,1]]}'],
     "splatgl: error: --transform: give either 'rotate_deg' or 'rotation', not both (one would "
     "be ignored)"),
])
def test_meaningless_render_options(tmp_path, capsys, extra, line):
    expect_one_line(capsys, tmp_path, ["render", "-o", tmp_path / "x.png", *extra], line)


def test_compare_accepts_gsplat_only_against_a_reference(tmp_path, capsys):
    expect_one_line(capsys, tmp_path, ["compare", "--convention", "gsplat", "--against", "tile"],
                    "splatgl: error: --convention gsplat applies to the NumPy reference only; the "
                    "quad and tile renderers follow the inria rules (use --renderer reference)")
    rc, out, err = run_cli(capsys, "compare", "--convention", "gsplat", "--width", "48",
                           "--height", "32", "--json")
    assert rc == 0 and json.loads(out)["against"] == "reference"


@pytest.mark.parametrize("height, shown", [(20000, "64x20000"), (1e9, "64x1000000000")])
def test_camera_file_sizes_are_checked_like_options(tmp_path, capsys, height, shown):
    path = camera_file(tmp_path, height=height)
    expect_one_line(capsys, tmp_path, ["render", "--camera", path, "-o", tmp_path / "x.png"],
                    f"splatgl: error: {path}: fields 'width', 'height': image {shown} is larger "
                    "than splatgl renders (16384 pixels a side)")


def test_camera_file_pose_errors_reach_the_cli(tmp_path, capsys):
    w2c = look_at([0.0, 0.0, -3.0], [0.0, 0.0, 0.0])
    w2c[:3, :3] = 0.0  # singular: was a LinAlgError traceback
    path = camera_file(tmp_path, w2c=w2c)
    expect_one_line(capsys, tmp_path, ["render", "--camera", path, "-o", tmp_path / "x.png"],
                    f"splatgl: error: {path}: field 'world_to_camera' is singular "
                    "(determinant 0): not a rotation")


def test_other_aspect_is_refused_and_one_side_keeps_the_aspect(tmp_path, capsys):
    path = camera_file(tmp_path, width=64, height=48)
    expect_one_line(capsys, tmp_path, ["render", "--camera", path, "--width", "100", "--height",
                                       "100", "-o", tmp_path / "x.png"],
                    f"splatgl: error: --width 100 --height 100 would stretch {path}'s 64x48 view "
                    "(aspect 1.333, asked 1); give only one of them to scale keeping the aspect")
    out = tmp_path / "x.png"
    rc, stdout, _ = run_cli(capsys, "render", "--camera", path, "--width", "32", "-o", out)
    assert rc == 0 and "32x24" in stdout
    rc, stdout, _ = run_cli(capsys, "render", "--camera", path, "--width", "32", "--height", "24",
                            "-o", out, "--force")
    assert rc == 0 and "32x24" in stdout


def test_timings_show_counts_as_counts(tmp_path, capsys):
    rc, out, _ = run_cli(capsys, "render", "-o", tmp_path / "x.png", "--width", "48", "--height",
                         "32", "--timings", "--sort", "exact")   # the CPU order counts what it drew
    line = next(t for t in out.splitlines() if t.startswith("timings:"))
    assert "drawn 1,604, occlusion_culled 0, cull_build " in line
    assert "drawn 1604" not in line and " ms, drawn" in line
    rc, out, _ = run_cli(capsys, "render", "-o", tmp_path / "x.png", "--width", "48", "--height",
                         "32", "--timings", "--renderer", "tile", "--force")
    line = next(t for t in out.splitlines() if t.startswith("timings:"))
    n_keys = line.split("n_keys ")[1].split(" ")[0].rstrip(",")
    assert n_keys.replace(",", "").isdigit() and "ms" not in n_keys


# ------------------------------------------------------------------------------ outputs
def test_same_output_twice_and_directory_outputs(tmp_path, capsys):
    out = tmp_path / "x.png"
    expect_one_line(capsys, tmp_path, ["render", "-o", out, "--depth-png", out],
                    f"splatgl: error: --depth-png {out}: the same file as -o; give each output "
                    "its own name")
    folder = tmp_path / "folder"
    folder.mkdir()
    expect_one_line(capsys, tmp_path, ["render", "-o", folder],
                    f"splatgl: error: -o {folder}: is a directory; give a file name")
    video = tmp_path / "v.mp4"          # a folder named like a video, --force or not:
    video.mkdir()                       # refused before any frame renders (none is left)
    for extra in ([], ["--workers", "2"]):
        expect_one_line(capsys, tmp_path, ["render", "--path", "orbit:3", "-o", video, "--width",
                                           "16", "--height", "16", "--force", *extra],
                        f"splatgl: error: -o {video}: is a directory; give a file name")
    assert sorted(os.listdir(tmp_path)) == ["folder", "v.mp4"] and not os.listdir(video)
    expect_one_line(capsys, tmp_path, ["compare", "--side-by-side", out, "--heatmap", out],
                    f"splatgl: error: --heatmap {out}: the same file as --side-by-side; give each "
                    "output its own name")
    missing = tmp_path / "nope" / "x.png"
    expect_one_line(capsys, tmp_path, ["render", "-o", missing],
                    f"splatgl: error: -o {missing}: folder {missing.parent} does not exist")


def test_compare_refuses_an_image_name_before_rendering(tmp_path, capsys, monkeypatch):
    """--side-by-side x.bmp failed only after both renders."""
    from splatgl.commands import compare as compare_cmd

    monkeypatch.setattr(compare_cmd, "Renderer", lambda: pytest.fail("rendered before the check"))
    out = tmp_path / "x.bmp"
    for option in ("--side-by-side", "--heatmap"):
        expect_one_line(capsys, tmp_path, ["compare", option, out],
                        f"splatgl: error: {option} {out}: unsupported image format ('.bmp'); "
                        "use .png, .tif, .tiff or .exr")


@pytest.mark.parametrize("command", ["render", "compare"])
def test_a_failed_second_file_leaves_neither(tmp_path, capsys, monkeypatch, command):
    from splatgl.commands import compare as compare_cmd
    from splatgl.commands import render as render_cmd
    from splatgl.errors import SplatglError

    module = render_cmd if command == "render" else compare_cmd
    real = module.write_image
    calls = []

    def failing_second(path, *a, **k):
        calls.append(path)
        if len(calls) == 2:
            raise SplatglError(f"{path}: writing failed: disk full")
        return real(path, *a, **k)

    monkeypatch.setattr(module, "write_image", failing_second)
    a, b = tmp_path / "a.png", tmp_path / "b.png"
    argv = (["render", "-o", a, "--depth-png", b] if command == "render"
            else ["compare", "--side-by-side", a, "--heatmap", b])
    rc, out, err = run_cli(capsys, *argv, "--width", "40", "--height", "30")
    assert rc == 2 and err.count("\n") == 1 and "disk full" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # neither file, no temporaries


def test_compare_says_which_pictures_it_wrote(tmp_path, capsys):
    a, b = tmp_path / "a.png", tmp_path / "b.png"
    rc, out, _ = run_cli(capsys, "compare", "--side-by-side", a, "--heatmap", b, "--width", "40",
                         "--height", "30")
    assert rc == 0 and f"wrote {a} (side by side: " in out
    assert f"wrote {b} (error heatmap, top of its scale at |err| 0.0157)" in out


def test_render_writes_both_files_on_success(tmp_path, capsys):
    a, b = tmp_path / "a.exr", tmp_path / "b.png"
    rc, out, _ = run_cli(capsys, "render", "-o", a, "--depth-png", b, "--width", "40", "--height", "30")
    assert rc == 0 and a.stat().st_size > 0 and b.stat().st_size > 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.exr", "b.png"]


# ------------------------------------------------------------------------------ bench
def test_bench_arguments_fail_before_measuring(tmp_path, capsys):
    existing = tmp_path / "results"
    existing.write_text("keep me")
    expect_one_line(capsys, tmp_path, ["bench", "--quick", "--out", existing],
                    f"splatgl: error: --out {existing}: is a file; --out names a folder for "
                    "bench.csv, bench.json and bench.png")
    expect_one_line(capsys, tmp_path, ["bench", "--quick", "--groups", "bogus,extent"],
                    "splatgl: error: --groups: unknown group(s) bogus; valid: precision, extent, "
                    "sort, sh, storage, resort, preprocess, cull, early-stop, projection, renderer")
    expect_one_line(capsys, tmp_path, ["bench", "--synthetic", "-5"],
                    "splatgl: error: argument --synthetic: must be 0 or more, got -5 "
                    "(see splatgl bench --help)")
    expect_one_line(capsys, tmp_path, ["bench", "--width", "0", "--frames", "0"],
                    "splatgl: error: argument --width: must be at least 1, got 0 "
                    "(see splatgl bench --help)")
    expect_one_line(capsys, tmp_path, ["bench", "--frames", "0"],
                    "splatgl: error: argument --frames: must be at least 1, got 0 "
                    "(see splatgl bench --help)")
    assert existing.read_text() == "keep me"


def test_bench_group_other_than_renderer_finishes_and_writes(tmp_path, capsys):
    out = tmp_path / "res"
    rc, stdout, err = run_cli(capsys, "bench", "--quick", "--groups", "extent", "--width", "32",
                              "--height", "24", "--frames", "1", "--out", out)
    assert rc == 0, err
    data = json.loads((out / "bench.json").read_text())
    assert {r["config"] for r in data["rows"]} == {"default", "extent=square", "limit"}
    assert stdout.startswith("machine: ") and data["machine"]["gl_renderer"] in stdout
    assert sorted(p.name for p in out.iterdir()) == ["bench.csv", "bench.json", "bench.png"]


def test_zero_sizes_and_closed_renderers_are_one_line_errors(tmp_path, capsys):
    """They were tracebacks: ZeroDivisionError from `path orbit --width 0` and from
    default_camera(scene, 0, 0); AttributeError from a Renderer used after close()."""
    from splatgl.commands._common import demo_scene_path
    from splatgl.errors import CameraError, SplatglError
    from splatgl.formats import load_scene
    from splatgl.api import Renderer, default_camera

    expect_one_line(capsys, tmp_path, ["path", "orbit", "--width", "0", "-o", tmp_path / "p.json"],
                    "splatgl: error: argument --width: must be at least 1, got 0 "
                    "(see splatgl path orbit --help)")
    scene = load_scene(demo_scene_path())
    for size, field in (((0, 0), "width"), ((8, 0), "height"), ((8.5, 4), "width")):
        with pytest.raises(CameraError, match=f"^camera {field} must be a positive integer, got"):
            default_camera(scene, *size)
    with pytest.raises(CameraError, match=r"^--fov must be in \(0, 180\) degrees, got 0"):  # the CLI's
        default_camera(scene, 8, 8, 0.0)
    camera = default_camera(scene, 16, 12)
    with Renderer() as renderer:
        assert renderer.render(scene, camera).shape == (12, 16, 4)
    renderer.close()  # a second close does nothing
    for call in (lambda: renderer.render(scene, camera), lambda: next(renderer.render_many(scene, [camera])),
                 lambda: renderer.render_layers(scene, camera)):
        with pytest.raises(SplatglError, match="^this Renderer is closed"):
            call()


def test_output_names_and_folders_are_checked_before_the_work(tmp_path, capsys, monkeypatch):
    """`render -o x.bmp` (or no suffix) failed after rendering, `lod -o nodir/x.lod.ply` after
    building the hierarchy."""
    import splatgl.commands.render as render_command
    import splatgl.lod.build as lod_build
    from splatgl.commands._common import demo_scene_path

    monkeypatch.setattr(render_command, "inputs_from_args", lambda args: pytest.fail("rendered"))
    monkeypatch.setattr(lod_build, "build_hierarchy", lambda *a, **k: pytest.fail("built"))
    for name, shown in (("x.bmp", "'.bmp'"), ("x", "no suffix")):
        expect_one_line(capsys, tmp_path, ["render", "-o", tmp_path / name],
                        f"splatgl: error: -o {tmp_path / name}: unsupported image format ({shown}); "
                        "use .png, .tif, .tiff or .exr")
    out = tmp_path / "nodir" / "x.lod.ply"
    expect_one_line(capsys, tmp_path, ["lod", demo_scene_path(), "-o", out],
                    f"splatgl: error: -o {out}: folder {out.parent} does not exist")
    expect_one_line(capsys, tmp_path, ["convert", demo_scene_path(), out.with_name("x.spz")],
                    f"splatgl: error: {out.with_name('x.spz')}: folder {out.parent} does not exist")


# ------------------------------------------------------------------------------ extreme numbers
FRAME = "splatgl: error: cannot frame the scene: the camera would stand "


@pytest.mark.parametrize("extra, line", [
    (["--near", "1e308"],
     "splatgl: error: --near 1e+308: must be at most 3.403e+38 (the largest depth a float32 holds)"),
    (["--near", "1e39"],
     "splatgl: error: --near 1e+39: must be at most 3.403e+38 (the largest depth a float32 holds)"),
    (["--distance", "1e308"],
     FRAME + "inf from it (scene radius 2.5, distance scale 1e+308); splatgl places it from 1e-09 "
     "to 5e+17 away (float arithmetic)"),
    (["--projection", "orthographic", "--distance", "1e300"],
     FRAME + "6.22e+300 from it (scene radius 2.5, distance scale 1e+300); splatgl places it from "
     "1e-09 to 5e+17 away (float arithmetic)"),
    (["--distance", "1e-300"],
     FRAME + "6.22e-300 from it (scene radius 2.5, distance scale 1e-300); splatgl places it from "
     "1e-09 to 5e+17 away (float arithmetic)"),
])
def test_extreme_numbers_are_one_line_not_numpy_warnings(tmp_path, capsys, extra, line):
    """Issue 38: `--near 1e308` and `--distance 1e308` leaked NumPy overflow warnings (here
    warnings are errors, so a leak fails the test)."""
    expect_one_line(capsys, tmp_path, ["render", "-o", tmp_path / "x.png", *extra], line)


@pytest.mark.parametrize("field, value, line", [
    ("fx", 1e300, "camera fx must be from 1e-09 to 1e+18 pixels (float32 arithmetic), got 1e+300"),
    ("fx", 1e-300, "camera fx must be from 1e-09 to 1e+18 pixels (float32 arithmetic), got 1e-300"),
    ("cx", -1e39, "camera cx must be within +-1e+18 pixels (float32 arithmetic), got -1e+39"),
    ("t", 1e300, "world_to_camera holds 1e+300 at row 2, column 3 (the camera is that far from the "
                 "origin); splatgl renders within 1e+18 (float32 arithmetic)"),
])
def test_camera_file_numbers_beyond_float32_are_one_line(tmp_path, capsys, field, value, line):
    """fx 1e300 was an OverflowError traceback, a translation of 1e300 a NumPy warning."""
    w2c = look_at([0.0, -0.5, -3.0], [0.0, 0.0, 0.0])
    if field == "t":
        w2c[2, 3] = value
    path = camera_file(tmp_path, w2c=w2c)
    if field != "t":
        path.write_text(json.dumps(dict(json.loads(path.read_text()), **{field: value})))
    expect_one_line(capsys, tmp_path, ["render", "--camera", path, "-o", tmp_path / "x.png"],
                    f"splatgl: error: {path}: {line}")


@pytest.mark.parametrize("extra", [
    ["--near", "1e-300"], ["--near", "3.4e38"], ["--distance", "1e16"], ["--fov", "179.9"],
    ["--background", "3.4e38,0,0"], ["--renderer", "reference", "--near", "3.4e38"],
    ["--renderer", "cpu", "--distance", "1e16"], ["--renderer", "tile", "--near", "1e-300"],
])
def test_extreme_but_valid_numbers_render_without_a_warning(tmp_path, capsys, extra):
    rc, out, err = run_cli(capsys, "render", "-o", tmp_path / "x.png", "--width", "16",
                           "--height", "12", *extra)
    assert (rc, err) == (0, "") and out.startswith(f"wrote {tmp_path / 'x.png'} (16x12")


def _numpy_overflow(args):
    np.float32(np.array([1e39]))  # float32 overflow: a RuntimeWarning, shown once per run
    np.array([1e39]).astype(np.float32)
    np.array([0.0]) / 0.0
    return 0


def test_a_numpy_warning_that_escapes_is_one_splatgl_line(capsys, monkeypatch):
    """The CLI-wide net: NumPy's floating-point warnings never reach the user raw; one line per
    run says where, and SPLATGL_DEBUG_WARNINGS=1 shows NumPy's own."""
    from splatgl.commands import render as render_command

    monkeypatch.setattr(render_command, "run", _numpy_overflow)
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        assert main(["render", "-o", "unused.png"]) == 0
    out, err = capsys.readouterr()
    assert re.fullmatch(r"splatgl: warning: a computation went out of range at (\S+/)?"
                        r"test_cli_errors\.py:\d+ \(NumPy: overflow encountered in cast\); the "
                        r"output may hold inf or NaN values\. Please report it with the command "
                        r"\(SPLATGL_DEBUG_WARNINGS=1 shows every such warning\)\n", err), err
    monkeypatch.setenv("SPLATGL_DEBUG_WARNINGS", "1")
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        assert main(["render", "-o", "unused.png"]) == 0
    out, err = capsys.readouterr()
    assert err.count("RuntimeWarning: overflow encountered in cast") == 2
    assert "RuntimeWarning: invalid value encountered in divide" in err


def test_glfw_errors_are_decoded_into_one_splatgl_line():
    """pyGLFW warns with "(65550) b'X11: ...'": the CLI prints the text, not the bytes."""
    from splatgl.cli import _warning_text

    class GLFWError(UserWarning):
        pass

    assert _warning_text("(65550) b'X11: The DISPLAY environment variable is missing'",
                         GLFWError, "glfw/__init__.py", 1) == (
        "window system: X11: The DISPLAY environment variable is missing")
