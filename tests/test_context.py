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
    from splatgl.model.scene import Scene
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
