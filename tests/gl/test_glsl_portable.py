"""Every shader variant the suite compiled, checked by a second GLSL front-end.

Mesa is the only OpenGL driver the suite runs on, and it accepts some GLSL that other drivers
(NVIDIA's, AMD's) may refuse; a GPU machine is lent rarely and briefly, so a shader that fails
to compile there would cost the whole lend.  glslang (Khronos's reference compiler,
``glslangValidator``, Debian package glslang-tools) reads each preprocessed stage exactly as
this process handed it to Mesa (recorded by ``helpers.record_compiled_shaders``): every camera
model, precision, layer set, sort path and switch the other tests drew with.  The test runs
last (the ``last`` marker), after the others have compiled their variants, and draws a few
frames itself first, so that run alone it still checks the common paths.

Two gaps of glslang 12, not of the shaders, are allowed for:

- ``GL_EXT_shader_framebuffer_fetch`` (the quad path's ordered layers, used only where the
  driver lists it): glslang knows it only for OpenGL ES; such stages are counted and skipped;
- ``GL_ARB_shader_ballot`` (the radix sort's ``arb`` path): glslang declares its built-ins only
  from ``#version 450``, which the extension does not ask for (it needs GLSL 4.00); such stages
  are checked with the version line raised to 450.
"""

from __future__ import annotations

import re
import shutil
import subprocess

import pytest

from helpers import COMPILED_SHADERS, random_scene

GLSLANG = shutil.which("glslangValidator")
FETCH = "#extension GL_EXT_shader_framebuffer_fetch"
BALLOT = "#extension GL_ARB_shader_ballot"
#: Stages a glslang call checks (one process checks many in about 2 ms each).
BATCH = 200


def _draw_a_few_frames() -> None:
    """The quad path (CPU and device order), the tile renderer and the radix sort's paths."""
    from splatgl.api import Renderer
    from splatgl.cameras.camera import Camera
    from splatgl.scene.settings import RendererKind, RenderSettings, SortKey

    scene = random_scene(64, degree=1)
    camera = Camera.from_fov(32, 24, 60.0)
    with Renderer() as renderer:
        for kind in (RendererKind.QUAD, RendererKind.TILE):
            for sort in (SortKey.EXACT, SortKey.GPU):
                renderer.render(scene, camera, RenderSettings(sort_key=sort), kind=kind)


def glslang_errors(stages: dict[str, tuple[str, str, str]], folder) -> tuple[dict[str, str], int]:
    """({stage file and digest: glslang's error lines} for the stages glslang refuses, the
    number skipped for framebuffer fetch)."""
    files, skipped = {}, 0
    for digest, (ext, name, text) in sorted(stages.items()):
        if FETCH in text:
            skipped += 1
            continue
        if BALLOT in text:
            text = text.replace("#version 430 core", "#version 450 core", 1)
        path = folder / f"{digest[:12]}.{ext}"
        path.write_text(text)
        files[str(path)] = f"{name} ({digest[:12]})"
    errors: dict[str, str] = {}
    paths = list(files)
    for start in range(0, len(paths), BATCH):
        batch = paths[start:start + BATCH]
        done = subprocess.run([GLSLANG, *batch], capture_output=True, text=True, timeout=600)
        if done.returncode == 0:
            continue
        current = None   # glslang names each file on a line of its own, then its messages
        for line in (done.stdout + done.stderr).splitlines():
            if line in files:
                current = line
            elif current is not None and re.match(r"(ERROR|error):", line):
                errors.setdefault(files[current], "")
                errors[files[current]] += line + "\n"
        assert errors, f"glslang failed without naming an error:\n{done.stdout}{done.stderr}"
    return errors, skipped


@pytest.mark.last
@pytest.mark.skipif(GLSLANG is None, reason="glslangValidator not installed (Debian package "
                                            "glslang-tools)")
def test_every_shader_the_suite_compiled_is_valid_glsl_to_glslang(tmp_path):
    _draw_a_few_frames()
    stages = dict(COMPILED_SHADERS)
    names = {name for _, name, _ in stages.values()}
    assert {"quad.frag", "tile_rasterize.comp", "order_cull.comp"} <= names
    errors, skipped = glslang_errors(stages, tmp_path)
    assert not errors, "".join(f"{name}:\n{lines}" for name, lines in errors.items())
    assert skipped < len(stages)


def test_a_stage_glslang_refuses_is_named_with_its_error(tmp_path):
    """The check can fail: a stage with a type error is reported by its file, the rest pass."""
    if GLSLANG is None:
        pytest.skip("glslangValidator not installed (Debian package glslang-tools)")
    good = "#version 430 core\nlayout(local_size_x = 1) in;\nvoid main() {}\n"
    bad = good.replace("void main() {}", "void main() { uint x = 1.5; }")
    fetch = "#version 430 core\n" + FETCH + " : require\nvoid main() {}\n"
    errors, skipped = glslang_errors({"a" * 40: ("comp", "good.comp", good),
                                      "b" * 40: ("comp", "bad.comp", bad),
                                      "c" * 40: ("frag", "fetch.frag", fetch)}, tmp_path)
    assert list(errors) == [f"bad.comp ({'b' * 12})"] and "cannot convert" in errors[
        f"bad.comp ({'b' * 12})"]
    assert skipped == 1
