"""Failed writes (a full disk, simulated deterministically by the ``full_disk`` fixture) give
one line naming the user's file, exit code 2 and nothing half-written; a damaged file is never
taken for a complete one."""

from __future__ import annotations

import numpy as np
import pytest

from splatgl.cli import main
from splatgl.commands._common import demo_scene_path
from splatgl.errors import SplatglError
from splatgl.imagefiles.images import image_file_problem, read_image, write_image

SIZE = ["--width", "96", "--height", "64"]


def _image(h=64, w=96):
    return np.random.default_rng(0).random((h, w, 4)).astype(np.float32)


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    return err


@pytest.mark.parametrize("ext", ["png", "tif", "exr"])
def test_a_short_write_raises_naming_the_target_and_leaves_nothing(tmp_path, full_disk, ext):
    target = tmp_path / f"x.{ext}"
    with full_disk(3000), pytest.raises(SplatglError) as info:
        write_image(target, _image())
    message = str(info.value)
    assert message.startswith(f"{target}: cannot write") and "partial" not in message, message
    assert "\n" not in message
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("ext", ["png", "tif", "exr"])
def test_image_file_problem_finds_cut_and_other_files(tmp_path, ext):
    good = tmp_path / f"good.{ext}"
    write_image(good, _image())
    assert image_file_problem(good, 96, 64) is None
    assert image_file_problem(good, 64, 96) == "it is 96x64, not 64x96"
    data = good.read_bytes()
    for keep in (0, 100, len(data) // 2, len(data) - 1):
        cut = tmp_path / f"cut.{ext}"
        cut.write_bytes(data[:keep])
        problem = image_file_problem(cut, 96, 64)
        assert problem is not None and ("cut short" in problem or "empty" in problem
                                        or "not a readable image" in problem), (keep, problem)
    if ext != "exr":
        write_image(tmp_path / f"deep.{ext}", _image(), 16)
        assert image_file_problem(tmp_path / f"deep.{ext}", 96, 64, 3, 8) == \
            "it has 16 bits per channel, not 8"


def test_render_to_a_full_disk_fails_in_one_line(tmp_path, capsys, full_disk):
    out = tmp_path / "x.png"
    with full_disk(3000):
        code = main(["render", str(demo_scene_path()), *SIZE, "-o", str(out)])
    assert code == 2
    err = _one_line(capsys)
    assert err.startswith(f"splatgl: error: {out}: cannot write: the file is cut short"), err
    assert "wrote" not in capsys.readouterr().out and list(tmp_path.iterdir()) == []


def _path(tmp_path, *argv) -> int:
    return main(["render", str(demo_scene_path()), "--path", "orbit:4", *SIZE, *map(str, argv)])


def test_path_frames_to_a_full_disk_fail_and_resume_completes(tmp_path, capsys, full_disk):
    out = tmp_path / "fr"
    with full_disk(500):
        assert _path(tmp_path, "-o", out) == 2
    assert _one_line(capsys).startswith(f"splatgl: error: {out / '00000.png'}: cannot write")
    assert list(out.iterdir()) == []  # no frame, no temporary
    assert _path(tmp_path, "-o", out, "--resume") == 0
    assert "wrote 4 frames" in capsys.readouterr().out


def test_resume_renders_damaged_frames_again(tmp_path, capsys):
    """A frame file cut short (a full disk, a killed writer of another program) or empty is
    not taken for a finished frame."""
    whole, out = tmp_path / "whole", tmp_path / "fr"
    assert _path(tmp_path, "-o", whole) == 0 and _path(tmp_path, "-o", out) == 0
    data = (out / "00001.png").read_bytes()
    (out / "00001.png").write_bytes(data[: len(data) // 2])
    (out / "00002.png").write_bytes(b"")
    (out / "00003.png").unlink()
    capsys.readouterr()
    assert _path(tmp_path, "-o", out, "--resume") == 0
    assert "wrote 3 frames to" in (printed := capsys.readouterr().out)
    assert "1 already there, 2 damaged ones rendered again" in printed
    for k in range(4):
        np.testing.assert_array_equal(read_image(out / f"{k:05d}.png"), read_image(whole / f"{k:05d}.png"))


@pytest.mark.parametrize("workers", ["1", "2"])
def test_resume_refuses_frames_of_another_size_before_rendering(tmp_path, capsys, workers):
    out = tmp_path / "fr"
    assert _path(tmp_path, "-o", out) == 0
    (out / "00003.png").unlink()
    capsys.readouterr()
    assert main(["render", str(demo_scene_path()), "--path", "orbit:4", "--width", "64",
                 "--height", "48", "-o", str(out), "--resume", "--workers", workers]) == 2
    err = _one_line(capsys)
    assert err.startswith(f"splatgl: error: {out / '00000.png'}: it is 96x64, not 64x48 as this run "
                          "renders its frames; --resume only completes frames of the same kind"), err
    assert not (out / "00003.png").exists()  # refused before any frame was rendered


SCENE_NAMES = ["a.ply", "a.compressed.ply", "a.splat", "a.spz", "a.sog", "meta.json", "a.glb", "a.gltf"]


@pytest.mark.parametrize("name", SCENE_NAMES)
def test_scene_writers_fail_in_one_line_and_leave_nothing(tmp_path, full_disk, name):
    """Every format (the SOG folder form with its textures too) on a full disk: one line naming
    the file, not its temporary, and an empty folder (the folder form left its .webp files and
    a .partial behind)."""
    import warnings

    from splatgl.formats import load_scene, save_scene

    scene = load_scene(demo_scene_path())
    with warnings.catch_warnings(), full_disk(1500), pytest.raises(SplatglError) as info:
        warnings.simplefilter("ignore")
        save_scene(tmp_path / name, scene)
    assert str(info.value).startswith(f"{tmp_path / name}: cannot write"), info.value
    assert "partial" not in str(info.value) and list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("name", ["a.glb", "a.gltf", "a.sog", "meta.json"])
def test_a_writer_refusal_names_the_users_file(tmp_path, name):
    """glTF and SOG refuse 2DGS scenes; the message named save_scene's temporary."""
    from helpers import random_scene
    from splatgl.errors import SceneFormatError
    from splatgl.formats import save_scene
    from splatgl.scene.splats import SplatKind

    with pytest.raises(SceneFormatError) as info:
        save_scene(tmp_path / name, random_scene(5, kind=SplatKind.SURFEL_2D))
    assert str(info.value).startswith(f"{tmp_path / name}: field 'scale': ") and \
        "partial" not in str(info.value), info.value
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("name", ["a.ply", "a.compressed.ply", "a.spz", "a.sog", "a.glb"])
def test_written_problem_finds_a_scene_file_cut_short(tmp_path, name):
    import warnings

    from splatgl.formats import load_scene, save_scene
    from splatgl.formats.written import written_problem

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        save_scene(tmp_path / name, load_scene(demo_scene_path()))
    assert written_problem(tmp_path / name) is None
    data = (tmp_path / name).read_bytes()
    for keep in (0, 10, len(data) // 2, len(data) - 1):
        (tmp_path / "cut").write_bytes(data[:keep])
        assert written_problem(tmp_path / "cut") is not None, keep


def test_convert_lod_and_camera_files_on_a_full_disk(tmp_path, capsys, full_disk):
    from splatgl.cameras.camera_files import save_camera
    from splatgl.api import default_camera
    from splatgl.formats import load_scene

    out = tmp_path / "out"
    out.mkdir()
    for argv, target in ((["convert", str(demo_scene_path()), str(out / "meta.json")], out / "meta.json"),
                         (["lod", str(demo_scene_path()), "-o", str(out / "d.lod.ply")], out / "d.lod.ply")):
        with full_disk(1500):
            assert main(argv) == 2
        assert _one_line(capsys).startswith(f"splatgl: error: {target}: cannot write"), argv
        assert list(out.iterdir()) == []
    camera = default_camera(load_scene(demo_scene_path()), 64, 48)
    (out / "cam.json").write_text("old")
    with full_disk(100), pytest.raises(SplatglError, match=f"^{out / 'cam.json'}: cannot write"):
        save_camera(out / "cam.json", camera)
    assert [p.name for p in out.iterdir()] == ["cam.json"] and (out / "cam.json").read_text() == "old"


def test_video_to_a_full_or_read_only_folder_fails_in_one_line(tmp_path, capsys, full_disk, monkeypatch):
    """av.error.OSError came out as a traceback; the video's temporary is never named."""
    pytest.importorskip("av")
    out = tmp_path / "v.mp4"
    for limit in (0, 3000):  # nothing fits (the container header) / the disk fills while encoding
        with full_disk(limit):
            assert _path(tmp_path, "-o", out) == 2
        assert _one_line(capsys) == f"splatgl: error: {out}: cannot write (File too large)"
        assert list(tmp_path.iterdir()) == []
    import splatgl.imagefiles.frame_targets as frame_output

    real = frame_output.os.access
    monkeypatch.setattr(frame_output.os, "access", lambda p, mode: False if str(p) == str(tmp_path) else real(p, mode))
    assert _path(tmp_path, "-o", out) == 2
    assert _one_line(capsys) == f"splatgl: error: {tmp_path}: the output folder is not writable"


def test_a_folder_whose_mode_has_no_write_bit_is_read_only_even_to_root(tmp_path, capsys):
    """``splatgl lod SCENE`` run as root wrote its default output beside a scene in a
    ``dr-xr-xr-x`` shared folder (the superuser may write any folder); a folder whose mode lets
    nobody write it is refused as not writable, whoever runs splatgl."""
    import shutil

    shared = tmp_path / "shared"
    shared.mkdir()
    scene = shared / "s.ply"
    shutil.copy(demo_scene_path(), scene)
    shared.chmod(0o555)
    try:
        assert main(["lod", str(scene)]) == 2
        assert _one_line(capsys) == (f"splatgl: error: -o {shared / 's.lod.ply'}: folder {shared} "
                                     "is not writable")
        assert main(["render", str(scene), "-o", str(shared / "x.png")]) == 2
        assert "is not writable" in _one_line(capsys)
        assert sorted(p.name for p in shared.iterdir()) == ["s.ply"]
    finally:
        shared.chmod(0o755)
