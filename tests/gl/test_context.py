"""The one context factory: EGL, the OSMesa fallback, and a clear error listing what was tried."""

from __future__ import annotations

import ctypes.util

import numpy as np
import pytest

from splatgl.errors import ContextError
from splatgl.gl import context


def test_egl_context_is_gl43():
    try:
        ctx = context.create_headless_context("egl")
    except ContextError as exc:
        pytest.skip(f"EGL unavailable: {exc}")
    try:
        assert ctx.version_code >= 430
    finally:
        ctx.release()


@pytest.mark.skipif(ctypes.util.find_library("OSMesa") is None, reason="libOSMesa not installed")
def test_osmesa_fallback_renders_the_same(monkeypatch):
    from splatgl.api import Renderer
    from splatgl.scene.splats import Scene
    from splatgl.cameras.camera import Camera

    scene = Scene.from_activated(np.array([[0.0, 0, 3]]), np.array([[1.0, 0, 0, 0]]),
                                 np.array([[0.2, 0.1, 0.1]]), np.array([0.8]), np.zeros((1, 1, 3)))
    cam = Camera(32, 32, 30.0, 30.0, 16.0, 16.0)
    images = []
    for backend in ("egl", "osmesa"):
        ctx = context.create_headless_context(backend)
        with Renderer(ctx) as r:
            images.append(r.render(scene, cam))
        ctx.release()
    np.testing.assert_array_equal(images[0], images[1])

    # With EGL failing, the default order falls back to OSMesa.
    def broken():
        raise RuntimeError("no EGL display")

    monkeypatch.setitem(context._FACTORIES, context.Backend.EGL, broken)
    ctx = context.create_headless_context()
    assert ctx.version_code >= 430
    ctx.release()


def test_error_lists_every_backend(monkeypatch):
    for b in context.Backend:
        monkeypatch.setitem(context._FACTORIES, b, lambda b=b: (_ for _ in ()).throw(RuntimeError(f"{b.value} broke")))
    with pytest.raises(ContextError) as info:
        context.create_headless_context()
    msg = str(info.value)
    assert "egl: egl broke" in msg and "osmesa: osmesa broke" in msg


def test_unknown_backend_named():
    with pytest.raises(ContextError, match="unknown OpenGL backend 'vulkan'"):
        context.create_headless_context("vulkan")


# ------------------------------------------------------------------ image sizes the driver refuses
class RefusingContext:
    """A context whose driver refuses every texture with GL_OUT_OF_MEMORY (as llvmpipe does
    beyond about 1.5 GiB, whatever its GL_MAX_* limits say)."""

    info = {"GL_RENDERER": "fake GL", "GL_MAX_RENDERBUFFER_SIZE": 16384,
            "GL_MAX_TEXTURE_SIZE": 16384, "GL_MAX_VIEWPORT_DIMS": (16384, 16384)}

    def __init__(self):
        self.tried, self._error = [], "GL_NO_ERROR"

    @property
    def error(self):
        error, self._error = self._error, "GL_NO_ERROR"
        return error

    def texture(self, size, components, dtype):
        self.tried.append((size, dtype))
        self._error = "GL_OUT_OF_MEMORY"
        return type("Texture", (), {"release": lambda self: None})()


def test_a_colour_target_the_driver_refuses_is_named_before_any_work(monkeypatch):
    from splatgl.gl import limits
    from splatgl.renderers import registry

    monkeypatch.setattr(limits, "available_memory", lambda: None)
    ctx = RefusingContext()
    assert registry.image_size_problem(4096, 4096, "quad", ctx) is None  # 256 MiB: not tried
    assert ctx.tried == []
    assert registry.image_size_problem(8192, 8192, "quad", ctx, "rgba8") is None
    assert registry.image_size_problem(16384, 8192, "quad", ctx) == (
        "is larger than this OpenGL driver allocates (its RGBA32F colour target of 2.0 GiB was "
        "refused with GL_OUT_OF_MEMORY by fake GL)")
    assert registry.image_size_problem(16384, 8192, "quad", ctx, "rgba16f") == (
        "is larger than this OpenGL driver allocates (its RGBA16F colour target of 1.0 GiB was "
        "refused with GL_OUT_OF_MEMORY by fake GL)")
    assert ctx.tried == [((16384, 8192), "f4"), ((16384, 8192), "f2")]


def _llvmpipe(gl_renderer):
    name = gl_renderer.ctx.info.get("GL_RENDERER", "")
    if not name.startswith("llvmpipe"):
        pytest.skip(f"{name} may allocate a 2 GiB target (llvmpipe refuses it)")
    return name


def test_render_16384x8192_on_llvmpipe_is_one_line(gl_renderer, tmp_path, capsys):
    """Issue 38: a framebuffer-incomplete traceback; every side is within GL_MAX_* limits, but
    llvmpipe refuses the 2 GiB RGBA32F target (refused before allocating: cheap)."""
    from splatgl.cli import main

    name = _llvmpipe(gl_renderer)
    rc = main(["render", "--width", "16384", "--height", "8192", "-o", str(tmp_path / "x.png")])
    out, err = capsys.readouterr()
    assert (rc, out) == (2, "")
    assert err == ("splatgl: error: --width/--height: image 16384x8192 is larger than this OpenGL "
                   "driver allocates (its RGBA32F colour target of 2.0 GiB was refused with "
                   f"GL_OUT_OF_MEMORY by {name})\n")
    assert list(tmp_path.iterdir()) == []


def test_an_incomplete_framebuffer_is_one_line(gl_renderer, monkeypatch):
    """Whatever the check before the work misses, the driver's refusal at allocation is one line."""
    from splatgl.cameras.camera import Camera
    from splatgl.errors import SplatglError
    from splatgl.gl import limits
    from splatgl.scene.splats import Scene
    from splatgl.scene.settings import RenderSettings

    name = _llvmpipe(gl_renderer)
    monkeypatch.setattr(limits, "PROBE_BYTES", float("inf"))
    scene = Scene.from_activated(np.array([[0.0, 0, 3]]), np.array([[1.0, 0, 0, 0]]),
                                 np.array([[0.2, 0.1, 0.1]]), np.array([0.8]), np.zeros((1, 1, 3)))
    camera = Camera(16384, 8192, 9000.0, 9000.0, 8192.0, 4096.0)
    with pytest.raises(SplatglError) as info:
        gl_renderer.render(scene, camera, RenderSettings(early_stop="off"))
    assert str(info.value) == (
        f"image 16384x8192: this OpenGL driver ({name}) could not allocate its render targets "
        "(the framebuffer is not complete (INCOMPLETE_ATTACHMENT), GL_OUT_OF_MEMORY); render a "
        "smaller image")
    assert gl_renderer.ctx.error == "GL_NO_ERROR"  # the driver's error is not left for others


# ------------------------------------------------------------- splat buffers the driver cannot hold
def test_one_buffer_limit_per_driver():
    """llvmpipe reports a 128 MiB storage block but reads 2 GiB buffers (and crashes past them);
    a driver that reports less than 2 GiB is held to what it reports."""
    from splatgl.gl import limits

    llvmpipe = type("Ctx", (), {"info": {"GL_RENDERER": "llvmpipe (LLVM 15)",
                                         "GL_MAX_SHADER_STORAGE_BLOCK_SIZE": 2 ** 27}})()
    other = type("Ctx", (), {"info": {"GL_RENDERER": "other GL",
                                      "GL_MAX_SHADER_STORAGE_BLOCK_SIZE": 2 ** 27}})()
    assert limits.buffer_limit(llvmpipe) == (2 ** 31, "the most one buffer may hold on llvmpipe (LLVM 15)")
    assert limits.buffer_limit(other) == (2 ** 27, "GL_MAX_SHADER_STORAGE_BLOCK_SIZE of other GL")
    limits.check_splat_buffer(other, 2 ** 23, 2 ** 27, "x")   # at the limit: allowed


def test_a_splat_buffer_past_the_driver_limit_is_one_line(gl_renderer, monkeypatch, tmp_path, capsys):
    """bench --scale --lod at 100M splats: the SH buffer (18 GB at degree 3) crashed llvmpipe
    (SIGSEGV) in a child process.  Refused before allocating, as one line, nothing written; the
    demo scene (1,604 splats, degree 3: 180 bytes a splat of SH in float32) at exactly the limit
    renders."""
    from splatgl.cli import main
    from splatgl.gl import limits

    name = gl_renderer.ctx.info.get("GL_RENDERER", "?")
    out = tmp_path / "x.png"
    argv = ["render", "--width", "32", "--height", "24", "-o", str(out)]
    monkeypatch.setattr(limits, "MAX_BUFFER_BYTES", 1604 * 180 - 1)
    assert main(argv) == 2
    stdout, err = capsys.readouterr()
    assert stdout == ""
    assert err == ("splatgl: error: 1,604 splats need a GPU buffer of 288,720 bytes (SH degree 3 "
                   "at --gpu-storage float32, 180 bytes a splat), more than this OpenGL driver "
                   f"allows in one (288,719 bytes, the most one buffer may hold on {name}); draw "
                   "fewer splats (a smaller --lod-budget or --memory), store them smaller "
                   "(--gpu-storage compact) or use --renderer cpu\n")
    assert list(tmp_path.iterdir()) == []
    assert main([*argv, "--gpu-storage", "compact"]) == 0   # 90 bytes a splat of SH
    monkeypatch.setattr(limits, "MAX_BUFFER_BYTES", 1604 * 180)
    assert main([*argv, "--force"]) == 0
    assert out.exists()


def test_glfw_errors_are_collected_as_text_not_printed_raw():
    """pyGLFW's default prints each GLFW error as a raw ``(65544) b'X11: ...'`` warning; inside
    ``glfw_errors`` they are collected as text for the caller's one line (issue 38)."""
    import warnings

    glfw = pytest.importorskip("glfw")
    with warnings.catch_warnings(record=True) as shown:
        warnings.simplefilter("always")
        with context.glfw_errors() as errors:
            glfw.window_hint(0x7FFF0001, 0)  # an unknown hint, or "not initialized": an error
        assert shown == [] and len(errors) == 1
        assert isinstance(errors[0], str) and not errors[0].startswith("b'")
        assert "hint" in errors[0].lower() or "not initialized" in errors[0].lower()
        glfw.window_hint(0x7FFF0001, 0)  # pyGLFW's own reporting is back
    assert [type(w.message).__name__ for w in shown] == ["GLFWError"]
