"""Many frames in one process: `splatgl render --path` to folders, patterns and video; frame k
equals `splatgl render --camera` of the same camera bit for bit; --resume; interrupts leave only
complete frames and no partial video; Renderer.render_many."""

from __future__ import annotations

import json
import re
import signal
import sys

import numpy as np
import pytest

import splatgl
from splatgl.output.layers import Layer, with_layers
from splatgl.tasks import batch
from splatgl.cameras.camera_files import save_camera
from splatgl.cli import main
from splatgl.commands._common import demo_scene_path
from splatgl.formats import load_scene
from splatgl.imagefiles.images import read_image
from splatgl.paths import orbit

from helpers import signal_and_wait, start_gated

SIZE = ["--width", "96", "--height", "64"]


def _render(*argv) -> int:
    return main(["render", str(demo_scene_path()), *map(str, argv)])


@pytest.mark.parametrize("ext", ["png", "exr"])
def test_frame_k_equals_single_render_bit_for_bit(tmp_path, capsys, ext):
    assert _render("--path", "orbit:3", *SIZE, "-o", tmp_path / f"f_%03d.{ext}", "--background", "0.2,0.3,0.4") == 0
    assert "wrote 3 frames" in capsys.readouterr().out
    cams = orbit(load_scene(demo_scene_path()), 3, 96, 64)
    for k, cam in enumerate(cams):
        save_camera(tmp_path / "cam.json", cam)
        assert _render("--camera", tmp_path / "cam.json", "-o", tmp_path / f"one.{ext}", "--background",
                       "0.2,0.3,0.4", "--force") == 0
        got, single = read_image(tmp_path / f"f_{k:03d}.{ext}"), read_image(tmp_path / f"one.{ext}")
        assert got.shape == single.shape == (64, 96, 5 if ext == "exr" else 3)
        np.testing.assert_array_equal(got, single)


def test_dataset_source_with_select_and_resume(tmp_path, capsys):
    """Frame files carry the camera's own index in the source, so a selection's frames land
    where the whole path's would."""
    from splatgl.datasets import colmap
    from splatgl.datasets.named_camera import NamedCamera

    cams = orbit(load_scene(demo_scene_path()), 10, 96, 64)
    colmap.write_colmap(tmp_path / "data" / "sparse" / "0", [NamedCamera(f"{k}.png", c) for k, c in enumerate(cams)])
    out = tmp_path / "frames"
    assert _render("--path", tmp_path / "data", "--select", "0:10:3", "-o", out) == 0
    names = sorted(p.name for p in out.iterdir())
    assert names == ["00000.png", "00003.png", "00006.png", "00009.png"]
    first = read_image(out / "00003.png")
    (out / "00006.png").unlink()
    before = {p.name: p.stat().st_mtime_ns for p in out.iterdir()}
    capsys.readouterr()
    assert _render("--path", tmp_path / "data", "--select", "0:10:3", "-o", out, "--resume") == 0
    printed = capsys.readouterr().out
    assert "wrote 1 frames" in printed and "3 already there" in printed
    assert {p.name: p.stat().st_mtime_ns for p in out.iterdir() if p.name in before} == before
    assert (out / "00006.png").is_file()
    np.testing.assert_array_equal(read_image(out / "00003.png"), first)


def test_a_path_rendered_in_parts_equals_the_whole(tmp_path, capsys):
    """`--select 0:3` then `--select 3:5 --resume` into one folder gives every frame, equal to
    the whole path's (frames were numbered within the selection: the second part wrote
    nothing, "3 already there", or overwrote the first)."""
    path = tmp_path / "p.json"
    assert main(["path", "orbit", str(demo_scene_path()), "--frames", "5", *SIZE, "-o", str(path)]) == 0
    assert _render("--path", path, "--select", "0:3", "-o", tmp_path / "parts") == 0
    capsys.readouterr()
    assert _render("--path", path, "--select", "3:5", "-o", tmp_path / "parts", "--resume") == 0
    assert "wrote 2 frames" in capsys.readouterr().out
    assert _render("--path", path, "-o", tmp_path / "whole") == 0
    names = sorted(p.name for p in (tmp_path / "whole").iterdir())
    assert names == [f"{k:05d}.png" for k in range(5)]
    assert sorted(p.name for p in (tmp_path / "parts").iterdir()) == names
    for name in names:
        np.testing.assert_array_equal(read_image(tmp_path / "parts" / name),
                                      read_image(tmp_path / "whole" / name))


def test_video_output(tmp_path, capsys):
    av = pytest.importorskip("av")
    from splatgl.imagefiles.video import read_video_frames

    assert _render("--path", "orbit:5", *SIZE, "-o", tmp_path / "o.mp4", "--fps", "12") == 0
    assert _render("--path", "orbit:5", *SIZE, "-o", tmp_path / "png") == 0
    frames = read_video_frames(tmp_path / "o.mp4")
    assert len(frames) == 5 and frames[0].shape == (64, 96, 3)
    with av.open(str(tmp_path / "o.mp4")) as c:
        assert c.streams.video[0].codec_context.name == "h264" and float(c.streams.video[0].average_rate) == 12
    for k, f in enumerate(frames):
        png = read_image(tmp_path / "png" / f"{k:05d}.png")
        # H.264 at crf 18 with 4:2:0 chroma: small mean error, measured 1.5-2.5 / 255
        assert np.abs(f / 255.0 - png).mean() < 5 / 255
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o.mp4", "png"]  # no partial file left


@pytest.mark.parametrize("argv, message", [
    (["--path", "orbit:2", "-o", "{t}/x.png"], "many frames need a folder or a pattern such as"),
    (["--path", "orbit:2", "-o", "{t}/x_%d_%d.png"], "needs exactly one integer field"),
    (["--path", "orbit:2", "-o", "{t}/f.avi"], "{t}/f.avi: unknown output type '.avi'; give a video "
     "(.mp4, .mov, .mkv), a frame pattern such as f_%05d.png (.png, .tif, .tiff, .exr) or a folder "
     "(a name without a suffix, or ending in /)"),
    (["--path", "orbit:2", "-o", "{t}/f.jpg"], "{t}/f.jpg: unknown output type '.jpg'"),
    (["--path", "orbit:2", "-o", "{t}/x.mp4", "--resume"], "a video rendered in one process cannot be resumed"),
    (["--path", "orbit:2", "-o", "{t}/x.mp4", "--width", "95", "--height", "64", "--workers", "2"],
     "needs an even width and height, got 95x64"),
    (["--path", "orbit:2", "-o", "{t}/f", "--ray-gpus", "1"], "--ray-address and --ray-gpus need --executor ray"),
    (["--path", "orbit:2", "-o", "{t}/f", "--workers", "0"], "--workers must be at least 1, got 0"),
    (["--path", "orbit:2", "-o", "{t}/x.mp4", "--width", "95", "--height", "64"], "needs an even width and height, got 95x64"),
    (["--path", "orbit:x", "-o", "{t}/f"], "expected orbit or orbit:FRAMES"),
    (["--path", "{t}/none.json", "-o", "{t}/f"], "none.json: no such file or folder"),
    (["--path", "orbit:2", "--camera", "c.json", "-o", "{t}/f"], "--camera and --path exclude each other"),
])
def test_bad_path_arguments_one_line(tmp_path, capsys, argv, message):
    assert _render(*[a.replace("{t}", str(tmp_path)) for a in argv]) == 2
    err = capsys.readouterr().err
    assert message.replace("{t}", str(tmp_path)) in err and len(err.strip().splitlines()) == 1, err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("size, message", [
    (("95", "64"), "needs an even width and height, got 95x64"),
    (("96", "64"), "video output needs PyAV: pip install 'splatgl[video]'"),
])
def test_without_pyav_a_wrong_video_size_is_named_before_the_install_hint(tmp_path, capsys,
                                                                          monkeypatch, size, message):
    monkeypatch.setitem(sys.modules, "av", None)     # import av fails
    argv = ["--path", "orbit:2", "-o", f"{tmp_path}/x.mp4", "--width", size[0], "--height", size[1]]
    assert _render(*argv) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1, err
    assert list(tmp_path.iterdir()) == []


def test_interrupt_leaves_complete_frames_only_and_resume_finishes(tmp_path, monkeypatch, capsys):
    real = batch.FrameMeter.__call__
    calls = []

    def interrupted(self, done, rendered):  # Ctrl-C arrives in the main thread after frame 3
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        real(self, done, rendered)

    monkeypatch.setattr(batch.FrameMeter, "__call__", interrupted)
    assert _render("--path", "orbit:6", *SIZE, "-o", tmp_path / "f") == 130
    left = sorted(p.name for p in (tmp_path / "f").iterdir())
    # Frame 0 was written before frame 2 was queued (the queue holds two); a frame the writer
    # had started finishes (atomically) and one still queued is dropped.  Which of frames 1-2
    # the writer thread had picked up when the interrupt came is a race between two threads (a
    # busy machine has left only frame 0), so: frames 0..k for some k <= 2, in order, whole, and
    # nothing else (no temporary files, no gap).
    assert 1 <= len(left) <= 3 and left == [f"{k:05d}.png" for k in range(len(left))], left
    for name in left:
        assert read_image(tmp_path / "f" / name).shape[:2] == (int(SIZE[3]), int(SIZE[1]))
    monkeypatch.setattr(batch.FrameMeter, "__call__", real)
    capsys.readouterr()
    assert _render("--path", "orbit:6", *SIZE, "-o", tmp_path / "f", "--resume") == 0
    assert f"wrote {6 - len(left)} frames" in capsys.readouterr().out
    assert _render("--path", "orbit:6", *SIZE, "-o", tmp_path / "g") == 0
    for k in range(6):
        np.testing.assert_array_equal(read_image(tmp_path / "f" / f"{k:05d}.png"),
                                      read_image(tmp_path / "g" / f"{k:05d}.png"))


def test_interrupt_removes_the_video(tmp_path, monkeypatch):
    pytest.importorskip("av")
    from splatgl.imagefiles import video

    real = video.VideoWriter.write
    calls = []

    def flaky(self, rgba):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        real(self, rgba)

    monkeypatch.setattr(video.VideoWriter, "write", flaky)
    assert _render("--path", "orbit:6", *SIZE, "-o", tmp_path / "v.mp4") == 130
    assert list(tmp_path.iterdir()) == []


def test_an_interrupted_path_says_on_its_line_what_it_left(tmp_path, monkeypatch, capsys):
    """Ctrl-C said only 'interrupted': now the frames a folder keeps and that --resume renders
    the rest, or that a video drawn in one process was not written (and how to keep frames)."""
    pytest.importorskip("av")
    from splatgl.imagefiles import video
    from splatgl.tasks import batch

    real, calls = batch.write_image, []

    def third_stops(*args, **kwargs):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(batch, "write_image", third_stops)
    capsys.readouterr()
    assert _render("--path", "orbit:6", *SIZE, "-o", tmp_path / "f") == 130
    kept = len(list((tmp_path / "f").iterdir()))   # the writer may have finished a later one
    assert 2 <= kept < 6 and capsys.readouterr().err == (
        f"splatgl: interrupted: {kept} of 6 frames are in {tmp_path / 'f'}/; the same command "
        "with --resume renders the rest\n")
    real_write = video.VideoWriter.write

    def third_frame_stops(self, rgba):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        real_write(self, rgba)

    monkeypatch.setattr(video.VideoWriter, "write", third_frame_stops)
    calls.clear()
    assert _render("--path", "orbit:6", *SIZE, "-o", tmp_path / "v.mp4") == 130
    assert capsys.readouterr().err == (f"splatgl: interrupted: no video written ({tmp_path / 'v.mp4'} "
                                       "is written once every frame is drawn; with --workers N its "
                                       "frames are kept for --resume)\n")


@pytest.mark.slow
def test_ctrl_c_on_a_real_process(tmp_path):
    """SIGINT while frames are being written (the process holds at its third frame until the
    signal: helpers.start_gated): exit 130, the two whole frames only, no temporary files."""
    out = tmp_path / "f"
    proc = start_gated(["render", str(demo_scene_path()), "--path", "orbit:400", "--width", "160",
                        "--height", "120", "-o", str(out)], frames=2)
    _, err = signal_and_wait(proc, signal.SIGINT)
    assert proc.returncode == 130, err
    assert sorted(p.name for p in out.iterdir()) == ["00000.png", "00001.png"]
    for p in out.iterdir():
        assert read_image(p).shape == (120, 160, 3)  # every file left is a whole image


def test_progress_reports_fps_and_eta(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("SPLATGL_PROGRESS", "1")
    assert _render("--path", "orbit:4", *SIZE, "-o", tmp_path / "f", "--timings") == 0
    out = capsys.readouterr()
    assert re.search(r"frames \(\d+\.\d\d fps, ETA [\d:]+\)", out.err), out.err  # any speed
    assert "100.0% (4 / 4)" in out.err
    assert "renderer stages" in out.out


def test_render_many_api_equals_render(gl_renderer):
    scene = load_scene(demo_scene_path())
    cams = orbit(scene, 3, 48, 32)
    many = list(gl_renderer.render_many(scene, cams))
    for cam, img in zip(cams, many):
        np.testing.assert_array_equal(img, gl_renderer.render(scene, cam))
    layers = next(gl_renderer.render_many(scene, cams[:1], layers=with_layers(Layer.DEPTH)))
    assert layers.depth.shape == (32, 48) and np.array_equal(layers.rgba, many[0])


def test_path_command_writes_files_render_reads(tmp_path, capsys):
    for gen, extra in (("orbit", [str(demo_scene_path())]), ("interpolate", ["--cameras", str(tmp_path / "o.json"), "--select", "0,2"])):
        for fmt in ("splatgl", "nerfstudio", "3dgs"):
            name = tmp_path / ("o.json" if gen == "orbit" and fmt == "splatgl" else f"{gen}_{fmt}.json")
            assert main(["path", gen, *extra, "--frames", "4", "--as", fmt, "-o", str(name),
                         *(["--width", "96", "--height", "64"] if gen == "orbit" else [])]) == 0
            cams = splatgl.load_cameras(name)
            assert len(cams) == 4 and (cams[0].width, cams[0].height) == (96, 64)
    orbit_cams = orbit(load_scene(demo_scene_path()), 4, 96, 64)
    for cam, got in zip(orbit_cams, splatgl.load_cameras(tmp_path / "o.json")):
        np.testing.assert_allclose(got.world_to_camera, cam.world_to_camera, atol=1e-12)
    inter = json.loads((tmp_path / "interpolate_splatgl.json").read_text())
    assert len(inter["keyframes"]) == 2 and inter["frames"] == 4  # an editable keyframe file
    capsys.readouterr()
    assert main(["path", "spiral", "--cameras", str(tmp_path / "o.json"), "-o", str(tmp_path / "bad.txt")]) == 2
    assert "path files are JSON" in capsys.readouterr().err


def test_path_orbit_takes_up_as_render_does(tmp_path, capsys):
    """``path orbit`` had no --up: a z-up scene's orbit file turned about -y while ``render
    --path orbit:N --up +z`` turned about z.  Now the file's frames are render's."""
    path = tmp_path / "o.json"
    assert main(["path", "orbit", str(demo_scene_path()), "--up", "+z", "--frames", "3",
                 *SIZE, "-o", str(path)]) == 0
    assert _render("--path", path, "-o", tmp_path / "file") == 0
    assert _render("--path", "orbit:3", *SIZE, "--up", "+z", "-o", tmp_path / "orbit") == 0
    for k in range(3):
        np.testing.assert_array_equal(read_image(tmp_path / "file" / f"{k:05d}.png"),
                                      read_image(tmp_path / "orbit" / f"{k:05d}.png"))
    cams = splatgl.load_cameras(path)
    assert cams[1].world_to_camera[1, 2] < -0.9   # the image's y (down) runs along -z


def test_path_sizes_follow_the_camera_rule(tmp_path, capsys):
    """--width and --height over a path's cameras: as with --camera, one of them scales keeping
    each camera's aspect and both must match it (they stretched the frames silently)."""
    path = tmp_path / "p.json"
    assert main(["path", "orbit", str(demo_scene_path()), "--frames", "2", *SIZE, "-o", str(path)]) == 0
    capsys.readouterr()
    assert _render("--path", path, "--width", "40", "--height", "40", "-o", tmp_path / "f") == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"splatgl: error: --width 40 --height 40 would stretch {path} (camera 0)'s 96x64 "
                   "view (aspect 1.5, asked 1); give only one of them to scale keeping the aspect")
    assert not (tmp_path / "f").exists()
    assert _render("--path", path, "--height", "32", "-o", tmp_path / "f") == 0
    assert _render("--path", path, "--width", "48", "--height", "32", "-o", tmp_path / "g") == 0
    assert read_image(tmp_path / "f" / "00001.png").shape == (32, 48, 3)
    np.testing.assert_array_equal(read_image(tmp_path / "f" / "00001.png"),
                                  read_image(tmp_path / "g" / "00001.png"))


def test_a_folder_with_a_dot_needs_the_slash(tmp_path, capsys):
    assert _render("--path", "orbit:2", *SIZE, "-o", f"{tmp_path / 'run.1'}/") == 0
    assert sorted(p.name for p in (tmp_path / "run.1").iterdir()) == ["00000.png", "00001.png"]


@pytest.mark.parametrize("layout, shape", [("side-by-side", (64, 192, 3)), ("top-bottom", (128, 96, 3))])
def test_stereo_paths_go_to_video_at_the_doubled_size(tmp_path, capsys, layout, shape):
    """Each video frame holds both eyes (it failed: "every video frame must be 96x64, got
    192x64")."""
    pytest.importorskip("av")
    from splatgl.imagefiles.video import read_video_frames

    stereo = ["--stereo", "0.05", "--stereo-layout", layout]
    assert _render("--path", "orbit:3", *SIZE, *stereo, "-o", tmp_path / "v.mp4") == 0
    assert f"({shape[1]}x{shape[0]}, " in capsys.readouterr().out
    assert _render("--path", "orbit:3", *SIZE, *stereo, "-o", tmp_path / "png") == 0
    frames = read_video_frames(tmp_path / "v.mp4")
    assert len(frames) == 3 and all(f.shape == shape for f in frames)
    for k, f in enumerate(frames):
        png = read_image(tmp_path / "png" / f"{k:05d}.png")
        assert png.shape == shape and np.abs(f / 255.0 - png).mean() < 5 / 255


def _mtimes(folder):
    return {p.name: p.stat().st_mtime_ns for p in folder.iterdir()}


def test_resume_refuses_frames_of_another_path_scene_or_options(tmp_path, capsys):
    """Each frame records the path, camera, scene and options it was rendered from
    (splatgl.imagefiles.frame_record): an orbit:6 folder resumed with orbit:8 (its frame 1 is
    another camera) or another --background stops before any work, in one line, and the
    frames are untouched; the same path resumes (a selection of it too)."""
    out = tmp_path / "f"
    assert _render("--path", "orbit:6", *SIZE, "-o", out) == 0
    (out / "00003.png").unlink()
    before = _mtimes(out)
    capsys.readouterr()
    assert _render("--path", "orbit:8", *SIZE, "-o", out, "--resume") == 2
    assert capsys.readouterr().err == (
        f"splatgl: error: {out}/00001.png: rendered with another camera (for --path orbit:6, not "
        "this run's --path orbit:8); --resume only completes frames of the same path, scene and "
        "options (render into another folder, or replace them: --force without --resume)\n")
    assert _render("--path", "orbit:6", *SIZE, "-o", out, "--resume", "--background", "1,0,0") == 2
    assert "00000.png: rendered with other render options (also for --path orbit:6)" in capsys.readouterr().err
    assert _mtimes(out) == before and not (out / "00003.png").exists()
    assert _render("--path", "orbit:6", *SIZE, "-o", out, "--resume", "--select", "2:5") == 0
    assert "wrote 1 frames to" in capsys.readouterr().out and (out / "00003.png").is_file()


def test_resume_takes_the_renderer_the_kept_frames_record(tmp_path, capsys):
    """--renderer auto could choose another renderer than the one that drew the frames kept
    (cpu once its kernels are compiled, else quad: here pinned to quad) and the run was refused
    as of other options: the frames record their renderer, and auto takes it up; naming another
    is refused in one line."""
    out = tmp_path / "f"
    assert _render("--path", "orbit:3", *SIZE, "-o", out, "--renderer", "tile", "--select", "0:2") == 0
    capsys.readouterr()
    before = _mtimes(out)
    assert _render("--path", "orbit:3", *SIZE, "-o", out, "--resume", "--renderer", "quad") == 2
    assert capsys.readouterr().err == (
        f"splatgl: error: --renderer quad: {out}/00000.png (--resume keeps it) was rendered by the "
        "tile renderer; leave --renderer out to complete the frames with it, or render into "
        "another folder\n")
    assert _mtimes(out) == before
    assert _render("--path", "orbit:3", *SIZE, "-o", out, "--resume", "--timings") == 0
    printed = capsys.readouterr().out
    assert f"wrote 1 frames to {out}/%05d.png, 2 already there (96x64" in printed
    assert ", tile, " in printed
    assert f"renderer auto -> tile (the renderer of {out}/00000.png, kept by --resume)" in printed


def test_resume_refuses_preview_drafts_and_keeps_unrecorded_frames(tmp_path, capsys):
    """Draft frames of --preview are recorded as such: an exact --resume does not keep them.
    Frames without a record (an older splatgl wrote them) are kept, as before, and the
    summary says how many could not be checked."""
    from splatgl.imagefiles.images import write_image

    out = tmp_path / "p"
    assert _render("--path", "orbit:2", *SIZE, "--preview", "--target-fps", "5000", "-o", out) == 0
    capsys.readouterr()
    assert _render("--path", "orbit:2", *SIZE, "-o", out, "--resume") == 2
    assert "00000.png: rendered with other render options" in capsys.readouterr().err
    old = tmp_path / "old"
    old.mkdir()
    write_image(old / "00000.png", np.zeros((64, 96, 4), np.float32))       # no record
    assert _render("--path", "orbit:2", *SIZE, "-o", old, "--resume") == 0
    assert ("wrote 1 frames to " f"{old}/%05d.png, 1 already there, 1 of them without a record of "
            "their path, scene and options to check (older splatgl)") in capsys.readouterr().out
