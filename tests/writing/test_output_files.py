"""All-or-nothing output files and the image-size limits, as units (the CLI cases are in
test_cli_errors.py)."""

from __future__ import annotations

import os

import pytest

from splatgl.gl import limits
from splatgl.errors import SplatglError
from splatgl.renderers.registry import image_size_problem
from splatgl.writing.outputs import OutputFiles
from splatgl.writing.atomic import atomic_target, atomic_write_text, temp_path


def test_commit_renames_every_temporary(tmp_path):
    files = OutputFiles({"-o": tmp_path / "a.png", "--x": tmp_path / "b.json", "--unset": None})
    with files:
        files.temp("-o").write_text("A")
        files.temp("--x").write_text("B")
        assert files.temp("-o").suffix == ".png" and files.temp("-o").parent == tmp_path
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.png", "b.json"]
    assert (tmp_path / "a.png").read_text() == "A"


@pytest.mark.parametrize("failure", [KeyboardInterrupt, OSError])
def test_failure_or_interrupt_leaves_nothing(tmp_path, failure):
    (tmp_path / "a.png").write_text("old")
    files = OutputFiles({"-o": tmp_path / "a.png", "--x": tmp_path / "b.json"}, overwrite=True)
    with pytest.raises(failure):
        with files:
            files.temp("-o").write_text("new")
            raise failure()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.png"]
    assert (tmp_path / "a.png").read_text() == "old"  # the old file is untouched


def test_a_declared_file_never_written_is_an_error(tmp_path):
    files = OutputFiles({"-o": tmp_path / "a.png", "--x": tmp_path / "b.json"})
    with pytest.raises(SplatglError, match=r"--x .*b.json: nothing was written"):
        with files:
            files.temp("-o").write_text("A")
            files.temp("--x")
    assert list(tmp_path.iterdir()) == []


def test_existing_files_without_overwrite(tmp_path):
    (tmp_path / "a.png").write_text("old")
    with pytest.raises(SplatglError) as info:
        OutputFiles({"image": tmp_path / "a.png"}, overwrite=False)
    assert str(info.value) == f"image {tmp_path / 'a.png'}: exists (use --force to replace it)"


def test_one_temporary_name_for_every_writer(tmp_path):
    """Hidden, beside the target, the suffix kept (OpenImageIO, PyAV and matplotlib pick the
    format by it), the process id in it; OutputFiles uses the same name."""
    tmp = temp_path(tmp_path / "view.lod.ply")
    assert tmp.parent == tmp_path and tmp.name.startswith(".view.lod.partial")
    assert tmp.suffix == ".ply" and str(os.getpid()) in tmp.name
    files = OutputFiles({"-o": tmp_path / "a.png"})
    with files:
        assert files.temp("-o") == temp_path(tmp_path / "a.png")
        files.temp("-o").write_text("A")


@pytest.mark.parametrize("failure", [KeyboardInterrupt, OSError, SplatglError])
def test_atomic_target_leaves_the_old_file_on_any_failure(tmp_path, failure):
    target = tmp_path / "a.json"
    atomic_write_text(target, "old")
    with pytest.raises(KeyboardInterrupt if failure is KeyboardInterrupt else SplatglError) as info:
        with atomic_target(target) as tmp:
            tmp.write_text("new")
            raise failure(28, "No space left on device") if failure is OSError else failure()
    if failure is OSError:  # one line naming the target, never the temporary
        assert str(info.value).startswith(f"{target}: cannot write (No space left on device")
    assert [p.name for p in tmp_path.iterdir()] == ["a.json"] and target.read_text() == "old"


def test_atomic_target_names_the_target_in_errors_and_checks(tmp_path):
    """A writer's error about the file it was handed (the temporary) names the user's file and
    keeps its class; a failed check does so too, and nothing is published."""
    from splatgl.errors import SceneFormatError

    target = tmp_path / "a.glb"
    with pytest.raises(SceneFormatError) as info:
        with atomic_target(target) as tmp:
            raise SceneFormatError(tmp, "bad", "scale")
    assert str(info.value) == f"{target}: field 'scale': bad" and info.value.path == str(target)
    with pytest.raises(SplatglError) as info:
        with atomic_target(target, lambda tmp: f"{tmp.name} is short") as tmp:
            tmp.write_text("x")
    assert str(info.value).startswith(f"{target}: cannot write: a.glb is short")
    assert list(tmp_path.iterdir()) == []


class FakeContext:
    def __init__(self, **info):
        self.info = {"GL_RENDERER": "fake GL", **info}


def test_context_limits_are_named():
    ctx = FakeContext(GL_MAX_RENDERBUFFER_SIZE=8192, GL_MAX_TEXTURE_SIZE=16384,
                      GL_MAX_VIEWPORT_DIMS=(16384, 16384), GL_MAX_SHADER_STORAGE_BLOCK_SIZE=2 ** 27)
    assert image_size_problem(8192, 100, "quad", ctx) is None
    assert image_size_problem(8193, 100, "quad", ctx) == (
        "is larger than this OpenGL driver allows (8192 pixels a side, GL_MAX_RENDERBUFFER_SIZE "
        "of fake GL)")
    # 16 bytes a pixel in one storage block of 128 MiB: 8,388,608 pixels at most.
    assert image_size_problem(4096, 2048, "tile", ctx) is None
    assert image_size_problem(4096, 2049, "tile", ctx) == (
        "has too many pixels for the tile renderer on this driver (8,392,704; its colour buffer "
        "of 16 bytes a pixel may hold 8,388,608, GL_MAX_SHADER_STORAGE_BLOCK_SIZE)")
    assert image_size_problem(16385, 1, "reference") == "is larger than splatgl renders (16384 pixels a side)"


def test_memory_is_checked_before_allocating(monkeypatch):
    monkeypatch.setattr(limits, "available_memory", lambda: 2 ** 30)
    assert image_size_problem(4000, 4000, "reference") is None  # 52 B a pixel: 0.77 GiB
    assert image_size_problem(6000, 4000, "reference") == (
        "needs at least 1.2 GiB of memory for its image buffers, 1.0 GiB available")


def test_screenshot_writes_png_and_json_together_or_not_at_all(tmp_path, gl_renderer, monkeypatch):
    from splatgl import default_camera
    from splatgl.cameras.camera_files import load_camera
    from splatgl.commands._common import demo_scene_path
    from splatgl.formats import load_scene
    from splatgl.scene.settings import RendererKind, RenderSettings
    from splatgl.viewer import screenshot

    scene = load_scene(demo_scene_path())
    camera = default_camera(scene, 40, 30)
    png, js, cmd = screenshot.save_screenshot(gl_renderer, scene, camera, RenderSettings(),
                                              RendererKind.QUAD, tmp_path)
    assert (png.name, js.name) == ("splatgl-view-0001.png", "splatgl-view-0001.json")
    assert load_camera(js).width == 40 and png.stat().st_size > 0

    def broken(path, *a, **k):
        raise SplatglError(f"{path}: writing failed: disk full")

    monkeypatch.setattr(screenshot, "write_image", broken)
    with pytest.raises(SplatglError, match="disk full"):
        screenshot.save_screenshot(gl_renderer, scene, camera, RenderSettings(), RendererKind.QUAD,
                                   tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([png.name, js.name])  # no lone JSON


def test_a_failed_write_in_the_block_names_the_target(tmp_path, full_disk):
    files = OutputFiles({"-o": tmp_path / "a.json", "--x": tmp_path / "b.txt"})
    with pytest.raises(SplatglError) as info:
        with files, full_disk(10):
            files.temp("-o").write_text("x" * 100)
    assert str(info.value).startswith(f"{tmp_path / 'a.json'}: cannot write (File too large")
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(SplatglError, match=f"^{tmp_path / 'b.txt'}: bad$"):
        with files:
            raise SplatglError(f"{files.temp('--x')}: bad")


def test_one_table_of_image_formats(tmp_path):
    """Suffixes, --format choices, channels and the layers a frame renders all come from
    imagefiles.image_formats: EXR holds the depth layer (Z), PNG and TIFF colour alone."""
    from splatgl.cli import build_parser
    from splatgl.imagefiles.frame_targets import FrameTarget
    from splatgl.imagefiles.image_formats import FORMAT_NAMES, IMAGE_SUFFIXES, image_format
    from splatgl.output.layers import Layer, with_layers

    assert FORMAT_NAMES == ("png", "tif", "exr")
    assert IMAGE_SUFFIXES == (".png", ".tif", ".tiff", ".exr")
    assert image_format("X.TIFF").name == "tif" and image_format("a.exr").is_float
    exr, png = image_format("a.exr"), image_format("a.png")
    assert exr.render_layers == with_layers(Layer.DEPTH) and png.render_layers == with_layers()
    assert exr.channels(exr.render_layers) == ("R", "G", "B", "A", "Z")
    assert exr.channels(with_layers()) == ("R", "G", "B", "A")
    assert png.channels(png.render_layers) == ("R", "G", "B")
    assert FrameTarget.parse(tmp_path / "f" / "%05d.exr").layers == with_layers(Layer.DEPTH)
    assert FrameTarget.parse(tmp_path / "f", "exr").layers == with_layers(Layer.DEPTH)
    assert FrameTarget.parse(tmp_path / "f", "tif").layers is None
    assert FrameTarget.parse(tmp_path / "f", "tiff").frame_path(3).name == "00003.tiff"
    render = build_parser()._subparsers._group_actions[0].choices["render"]
    assert next(a for a in render._actions if a.dest == "format").choices == FORMAT_NAMES
    with pytest.raises(SplatglError, match=r"^--format must be one of png, tif, exr; got 'bmp'$"):
        FrameTarget.parse(tmp_path / "f", "bmp")


# ------------------------------------------------------------------ outputs against inputs
@pytest.mark.parametrize("overwrite", [False, True])
def test_an_output_that_is_an_input_is_refused_even_with_overwrite(tmp_path, overwrite):
    cam = tmp_path / "cam.json"
    cam.write_text("{}")
    with pytest.raises(SplatglError) as info:
        OutputFiles({"--json": cam}, overwrite, inputs={"SCENE": None, "--camera": cam})
    assert str(info.value) == f"--json {cam}: the same file as --camera; give the output its own name"
    assert cam.read_text() == "{}"


def test_the_same_file_through_a_symbolic_or_hard_link(tmp_path):
    image = tmp_path / "qq.png"
    image.write_bytes(b"png")
    link, hard = tmp_path / "link.png", tmp_path / "hard.png"
    link.symlink_to(image)
    os.link(image, hard)
    (tmp_path / "sub").symlink_to(tmp_path, target_is_directory=True)
    for out in (link, hard, tmp_path / "sub" / "qq.png"):
        with pytest.raises(SplatglError) as info:
            OutputFiles({"--heatmap": out}, overwrite=True, inputs={"--image": image})
        assert str(info.value) == (f"--heatmap {out}: the same file as --image {image}; give the "
                                   "output its own name")
    with pytest.raises(SplatglError, match="the same file as --heatmap; give each output"):
        OutputFiles({"--heatmap": image, "-o": link}, overwrite=True)
    assert image.read_bytes() == b"png"


def test_a_folder_input_gives_its_files(tmp_path):
    photos = [tmp_path / "images" / f"{i}.png" for i in range(3)]
    photos[0].parent.mkdir()
    for p in photos:
        p.write_bytes(b"photo")
    with pytest.raises(SplatglError, match=r"--renders .*1.png: the same file as --dataset"):
        OutputFiles({"--renders": photos[1]}, overwrite=True, inputs={"--dataset": photos})
    OutputFiles({"--renders": tmp_path / "images" / "9.png"}, inputs={"--dataset": photos})


def test_check_output_path_refuses_inputs_and_existing_files(tmp_path):
    from splatgl.writing.outputs import check_output_path

    scene = tmp_path / "s.ply"
    scene.write_bytes(b"ply")
    with pytest.raises(SplatglError, match="the same file as IN; give the output its own name"):
        check_output_path(scene, "OUT", overwrite=True, inputs={"IN": scene})
    with pytest.raises(SplatglError, match="exists \\(use --force to replace it\\)"):
        check_output_path(scene, "OUT")
    check_output_path(scene, "OUT", overwrite=True, inputs={"IN": tmp_path / "other.ply"})


def test_a_link_is_written_through_to_its_target(tmp_path):
    """``-o link.ply --force`` replaced the link with a plain file; the target kept the old one."""
    target = tmp_path / "real" / "scene.ply"
    target.parent.mkdir()
    target.write_text("old")
    link = tmp_path / "link.ply"
    link.symlink_to(target)
    atomic_write_text(link, "new")
    assert link.is_symlink() and target.read_text() == "new"
    files = OutputFiles({"-o": link}, overwrite=True)
    with files:
        assert files.temp("-o").parent == target.parent
        files.temp("-o").write_text("newer")
    assert link.is_symlink() and target.read_text() == "newer"
    assert sorted(p.name for p in target.parent.iterdir()) == ["scene.ply"]


def test_a_failed_write_on_a_pseudo_file_system_is_not_a_full_disk():
    """``-o /proc/x.ply`` was reported as a full disk."""
    import errno

    from splatgl.writing.atomic import disk_note, write_error

    assert disk_note("/proc") == ""
    message = str(write_error("/proc/x.ply", OSError(errno.ENOENT, "No such file or directory")))
    assert message == "/proc/x.ply: cannot write (No such file or directory)"
