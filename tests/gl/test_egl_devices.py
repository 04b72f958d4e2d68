"""The EGL device choice: hardware first, SPLATGL_EGL_DEVICE overrides, the renderer named.

The chooser runs on fake device lists and fake contexts (this machine has only llvmpipe); the
override and the renderer line run end to end on the real EGL device.
"""

from __future__ import annotations

import pytest

from splatgl.errors import ContextError
from splatgl.gl import context, egl_devices
from splatgl.gl.egl_devices import EglDevice

SOFT = frozenset({"EGL_MESA_device_software", "EGL_EXT_device_drm_render_node"})
HARD = frozenset({"EGL_NV_device_cuda", "EGL_EXT_device_drm"})


class FakeContext:
    def __init__(self, renderer: str):
        self.info = {"GL_RENDERER": renderer}
        self.extra = None
        self.released = False
        self.entered = 0

    def release(self):
        self.released = True

    def __enter__(self):
        self.entered += 1
        return self


@pytest.fixture
def fake_egl(monkeypatch):
    """Install a fake device list; returns (set_devices, created) where ``created`` lists the
    device indices contexts were requested on, in order."""
    monkeypatch.delenv("SPLATGL_EGL_DEVICE", raising=False)
    monkeypatch.delenv("GLCONTEXT_DEVICE_INDEX", raising=False)
    monkeypatch.delenv("SPLATGL_GL_BACKEND", raising=False)
    created: list = []
    state = {"devices": None, "renderers": {}}

    def on(device):
        created.append(device)
        renderer = state["renderers"].get(device)
        if isinstance(renderer, Exception):
            raise renderer
        ctx = FakeContext(renderer or "llvmpipe (LLVM 15.0.6, 256 bits)")
        state.setdefault("contexts", {})[device] = ctx
        return ctx

    def set_devices(devices, renderers):
        state["devices"], state["renderers"] = devices, renderers
        return state

    monkeypatch.setattr(egl_devices, "query_devices", lambda: state["devices"])
    monkeypatch.setattr(context, "_egl_on", on)
    return set_devices, created


def test_hardware_device_is_chosen_before_software(fake_egl):
    set_devices, created = fake_egl
    set_devices([EglDevice(0, SOFT), EglDevice(1, HARD, "/dev/dri/renderD128")],
                {1: "NVIDIA H100 80GB HBM3/PCIe/SSE2"})
    ctx = context._create_egl()
    assert created == [1]  # the software device is never opened
    assert ctx.extra == {"egl_device": 1, "egl_devices": 2, "egl_skipped": []}
    assert context.renderer_name(ctx) == "NVIDIA H100 80GB HBM3/PCIe/SSE2 (EGL device 1 of 2)"


def test_a_device_that_fails_is_skipped(fake_egl):
    set_devices, created = fake_egl
    set_devices([EglDevice(0, HARD), EglDevice(1, HARD), EglDevice(2, SOFT)],
                {0: RuntimeError("eglInitialize failed (0x3001)"), 1: "NVIDIA A10G/PCIe/SSE2"})
    ctx = context._create_egl()
    assert created == [0, 1]
    assert ctx.info["GL_RENDERER"] == "NVIDIA A10G/PCIe/SSE2"
    assert ctx.extra["egl_skipped"] == ["device 0: eglInitialize failed (0x3001)"]


def test_software_renderer_on_a_hardware_device_is_the_last_resort(fake_egl):
    set_devices, created = fake_egl
    state = set_devices([EglDevice(0, SOFT), EglDevice(1, HARD)],
                        {1: "llvmpipe (LLVM 15.0.6, 256 bits)", 0: "softpipe"})
    ctx = context._create_egl()
    assert created == [1, 0]
    first, second = state["contexts"][1], state["contexts"][0]
    assert ctx is first and second.released and not first.released
    assert first.entered == 1  # made current again after the other one was released


def test_every_device_failing_is_one_line_listing_them(fake_egl):
    set_devices, _ = fake_egl
    set_devices([EglDevice(0, HARD), EglDevice(1, SOFT)],
                {0: RuntimeError("eglInitialize failed (0x3001)\nmore"), 1: RuntimeError("no")})
    with pytest.raises(ContextError) as info:
        context._create_egl()
    assert str(info.value) == ("no EGL device gave a context (device 0: eglInitialize failed "
                               "(0x3001); device 1: no)")


def test_single_device_uses_the_default(fake_egl):
    set_devices, created = fake_egl
    set_devices([EglDevice(0, SOFT)], {})
    ctx = context._create_egl()
    assert created == [None]
    assert context.renderer_name(ctx) == "llvmpipe (LLVM 15.0.6, 256 bits)"


def test_override_picks_the_device(fake_egl, monkeypatch):
    set_devices, created = fake_egl
    set_devices([EglDevice(0, HARD), EglDevice(1, SOFT)], {0: "NVIDIA H100"})
    monkeypatch.setenv("SPLATGL_EGL_DEVICE", "1")
    ctx = context._create_egl()
    assert created == [1]
    assert context.renderer_name(ctx) == "llvmpipe (LLVM 15.0.6, 256 bits) (EGL device 1 of 2)"


@pytest.mark.parametrize("value", ["2", "-1", "gpu"])
def test_bad_override_is_one_line_naming_the_devices(fake_egl, monkeypatch, value):
    set_devices, created = fake_egl
    set_devices([EglDevice(0, SOFT), EglDevice(1, HARD, "/dev/dri/renderD128")], {})
    monkeypatch.setenv("SPLATGL_EGL_DEVICE", value)
    with pytest.raises(ContextError) as info:
        context._create_egl()
    assert str(info.value) == (f"SPLATGL_EGL_DEVICE={value}: no such EGL device; EGL devices: "
                               "0 software, 1 hardware (/dev/dri/renderD128)")
    assert created == []


def test_override_disagreeing_with_glcontext_variable(monkeypatch):
    monkeypatch.setenv("SPLATGL_EGL_DEVICE", "1")
    monkeypatch.setenv("GLCONTEXT_DEVICE_INDEX", "0")
    with pytest.raises(ContextError, match="SPLATGL_EGL_DEVICE=1 and GLCONTEXT_DEVICE_INDEX=0 disagree"):
        egl_devices.override_text(__import__("os").environ)


def test_override_does_not_fall_back_to_osmesa(fake_egl, monkeypatch):
    set_devices, _ = fake_egl
    set_devices([EglDevice(0, SOFT)], {})
    monkeypatch.setitem(context._FACTORIES, context.Backend.OSMESA, lambda: FakeContext("osmesa"))
    monkeypatch.setenv("SPLATGL_EGL_DEVICE", "4")
    with pytest.raises(ContextError, match=r"tried egl: SPLATGL_EGL_DEVICE=4: no such EGL device; "
                                           r"EGL devices: 0 software$"):
        context.create_headless_context()
    with pytest.raises(ContextError, match="SPLATGL_EGL_DEVICE names an EGL device, but the "
                                           "OpenGL backend is osmesa"):
        context.create_headless_context("osmesa")


@pytest.mark.parametrize("name, software", [
    ("llvmpipe (LLVM 15.0.6, 256 bits)", True), ("softpipe", True),
    ("Mesa OffScreen (Software Rasterizer)", True), ("Google SwiftShader", True),
    ("NVIDIA H100 80GB HBM3/PCIe/SSE2", False), ("AMD Radeon RX 7900 XTX (radeonsi, navi31)", False),
    ("Mesa Intel(R) UHD Graphics 630 (CFL GT2)", False)])
def test_software_renderer_names(name, software):
    assert egl_devices.is_software_renderer(name) is software


def test_real_devices_are_listed_and_the_override_works_end_to_end(monkeypatch, tmp_path, capsys):
    """On this machine's EGL: the device list, SPLATGL_EGL_DEVICE=0 renders, an index past the
    list is one line from the CLI (exit 2) and --timings names the renderer."""
    from splatgl.cli import main

    devices = egl_devices.query_devices()
    if devices is None:
        pytest.skip("EGL device enumeration unavailable")
    assert [d.index for d in devices] == list(range(len(devices)))
    monkeypatch.delenv("GLCONTEXT_DEVICE_INDEX", raising=False)
    monkeypatch.delenv("SPLATGL_GL_BACKEND", raising=False)
    monkeypatch.setenv("SPLATGL_PROGRESS", "0")
    monkeypatch.setenv("SPLATGL_EGL_DEVICE", "0")
    out = tmp_path / "a.png"
    assert main(["render", "--width", "32", "--height", "24", "-o", str(out), "--timings"]) == 0
    text = capsys.readouterr().out
    ctx = context.create_headless_context()
    try:
        name = context.renderer_name(ctx)
    finally:
        ctx.release()
    assert f"GL renderer: {name}\n" in text and out.is_file()
    monkeypatch.setenv("SPLATGL_EGL_DEVICE", str(len(devices)))
    assert main(["render", "--width", "32", "--height", "24", "-o", str(tmp_path / "b.png")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert f"SPLATGL_EGL_DEVICE={len(devices)}: no such EGL device; EGL devices: 0 " in err
    assert not (tmp_path / "b.png").exists()
