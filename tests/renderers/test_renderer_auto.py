"""The fastest path on every device, by default (issue 40 item 4): the device class
(:mod:`splatgl.gl.device_class`), ``--sort auto``, ``--early-stop auto`` and ``--renderer auto``
(:mod:`splatgl.renderers.auto`), and what ``--timings`` says of them.

The suite pins ``--renderer auto`` to the quad path (tests/conftest.py); these tests unset that
and fake the device class and the CPU renderer's kernel cache, so nothing here depends on the
machine or on whether numba's cache is warm."""

from __future__ import annotations

import pytest

from helpers import random_scene
from splatgl.cli import main
from splatgl.errors import SplatglError
from splatgl.gl import device_class
from splatgl.gl.device_class import (Device, DeviceClass, choice_text, classify, resolve_early_stop,
                                     resolve_sort)
from splatgl.scene.splats import SplatKind
from splatgl.scene.settings import EarlyStop, Precision, RendererKind, RenderSettings, SortKey
from splatgl.output.layers import BASE, Layer
from splatgl.renderers import auto, cpu, kernel_build

SOFTWARE = Device(DeviceClass.SOFTWARE, "llvmpipe")
HARDWARE = Device(DeviceClass.HARDWARE, "NVIDIA H100 80GB HBM3")


class Spawned(list):
    """The processes :mod:`splatgl.renderers.kernel_build` started (argv, keywords), none run."""

    def __call__(self, argv, **kwargs):
        self.append((argv, kwargs))


@pytest.fixture
def spawned(monkeypatch, tmp_path):
    """The detached compile's processes recorded, not started; its stamp under tmp_path."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    record = Spawned()
    monkeypatch.setattr(kernel_build, "_spawn", record)
    return record


@pytest.fixture
def unpinned(monkeypatch, spawned):
    """``--renderer auto`` by the device's rule (the suite pins it to quad), the message not
    yet said, no device class forced, no compile process started."""
    monkeypatch.delenv(auto.PIN_ENV, raising=False)
    monkeypatch.delenv(device_class.CLASS_ENV, raising=False)
    monkeypatch.setattr(auto, "_told", False)
    return monkeypatch


@pytest.mark.parametrize("name, cls", [
    ("llvmpipe (LLVM 15.0.6, 256 bits)", DeviceClass.SOFTWARE),
    ("softpipe", DeviceClass.SOFTWARE),
    ("Mesa X11 swrast", DeviceClass.SOFTWARE),
    ("Google SwiftShader", DeviceClass.SOFTWARE),
    ("NVIDIA H100 80GB HBM3/PCIe/SSE2", DeviceClass.HARDWARE),
    ("AMD Radeon RX 7900 XTX (radeonsi, navi31, LLVM 17.0.6, DRM 3.57)", DeviceClass.HARDWARE),
])
def test_the_class_comes_from_the_gl_renderer_string(unpinned, name, cls):
    assert classify(name).cls is cls


def test_the_class_can_be_forced_and_a_bad_value_is_one_line(unpinned):
    unpinned.setenv(device_class.CLASS_ENV, "hardware")
    assert classify("llvmpipe (LLVM 15.0.6, 256 bits)") == Device(DeviceClass.HARDWARE, "llvmpipe")
    unpinned.setenv(device_class.CLASS_ENV, "gpu")
    with pytest.raises(SplatglError, match=r"^SPLATGL_DEVICE_CLASS=gpu: must be 'software' or "
                                           r"'hardware'$"):
        classify("llvmpipe")


def test_sort_auto_is_the_device_order_on_hardware_and_the_cpu_order_on_software():
    assert resolve_sort("auto", HARDWARE) is SortKey.GPU
    assert resolve_sort("auto", SOFTWARE) is SortKey.EXACT
    assert resolve_sort("bucket16", HARDWARE) is SortKey.BUCKET16     # given: kept
    assert choice_text("sort", "exact", SOFTWARE) == "sort auto -> exact (llvmpipe: software)"


def test_early_stop_auto_is_on_on_hardware_and_llvmpipes_rule_on_software():
    assert resolve_early_stop(EarlyStop.AUTO, HARDWARE) is EarlyStop.ON
    assert resolve_early_stop(EarlyStop.AUTO, SOFTWARE) is EarlyStop.AUTO
    assert resolve_early_stop(EarlyStop.OFF, HARDWARE) is EarlyStop.OFF


def _ready(monkeypatch, ready: bool) -> None:
    monkeypatch.setattr(cpu, "kernels_ready", lambda: ready)


def test_renderer_auto_is_cpu_on_software_where_it_can_draw_and_its_kernels_are_ready(unpinned):
    _ready(unpinned, True)
    choice = auto.choose(scene=random_scene(8), settings=RenderSettings(), device=SOFTWARE)
    assert (choice.kind, choice.kernels_missing) == (RendererKind.CPU, False)
    assert choice.text() == "renderer auto -> cpu (llvmpipe: software, cpu kernels ready)"


def test_renderer_auto_is_quad_on_hardware(unpinned):
    _ready(unpinned, True)
    choice = auto.choose(scene=random_scene(8), settings=RenderSettings(), device=HARDWARE)
    assert choice.kind is RendererKind.QUAD
    assert choice.text() == "renderer auto -> quad (NVIDIA H100 80GB HBM3: hardware)"


def test_renderer_auto_is_quad_where_the_cpu_renderer_cannot_draw_the_request(unpinned):
    _ready(unpinned, True)
    for request in ({"settings": RenderSettings(precision=Precision.RGBA16F)},   # quad-only option
                    {"settings": RenderSettings(sort_key=SortKey.GPU)},
                    {"settings": RenderSettings(early_stop=EarlyStop.ON)},
                    {"layers": frozenset(BASE | {Layer.NORMAL})},
                    {"under": True},
                    {"scene": random_scene(8, kind=SplatKind.SURFEL_2D)}):
        choice = auto.choose(device=SOFTWARE, **request)
        assert (choice.kind, choice.kernels_missing) == (RendererKind.QUAD, False), request
    why = auto.choose(device=SOFTWARE, settings=RenderSettings(precision="rgba16f")).why
    assert why == ("llvmpipe: software; the cpu renderer: --precision rgba16f applies to the quad "
                   "renderer only, not the cpu renderer, which would ignore it")


def test_renderer_auto_is_quad_until_the_kernels_are_compiled_and_says_so_once(unpinned, capsys):
    _ready(unpinned, False)
    choice = auto.choose(settings=RenderSettings(), device=SOFTWARE)
    assert (choice.kind, choice.kernels_missing) == (RendererKind.QUAD, True)
    auto.compiling_notice(choice, background=False)
    auto.compiling_notice(choice, background=False)
    assert capsys.readouterr().err == (
        "splatgl: the cpu renderer's kernels are not compiled yet (first use, about half a minute "
        "once: '--renderer cpu' compiles them); drawing with quad this time\n")


def test_the_pin_keeps_quad_and_a_bad_pin_is_one_line(unpinned):
    _ready(unpinned, True)
    unpinned.setenv(auto.PIN_ENV, "quad")
    assert auto.choose(device=SOFTWARE).kind is RendererKind.QUAD
    unpinned.setenv(auto.PIN_ENV, "fast")
    with pytest.raises(SplatglError, match=r"^SPLATGL_RENDERER_AUTO=fast: must be 'quad' or unset$"):
        auto.choose(device=SOFTWARE)


def test_kernels_ready_reads_this_process_and_numbas_cache(monkeypatch):
    monkeypatch.setattr(cpu, "_READY", True)
    assert cpu.kernels_ready()
    monkeypatch.setattr(cpu, "_READY", False)
    monkeypatch.setattr(cpu.importlib.util, "find_spec", lambda name: None)   # no numba
    assert not cpu.kernels_ready()


def _render(tmp_path, capsys, *extra):
    assert main(["render", "-o", str(tmp_path / "a.png"), "--width", "32", "--height", "24",
                 "--timings", "--force", *extra]) == 0
    return capsys.readouterr()


def test_timings_say_what_each_auto_chose(unpinned, tmp_path, capsys):
    unpinned.setenv(device_class.CLASS_ENV, "software")
    _ready(unpinned, False)
    got = _render(tmp_path, capsys)
    assert "(32x24, 1604 splats, quad)" in got.out
    assert "\nrenderer auto -> quad (" in got.out          # the device named as EGL lists it
    assert ": software; the cpu renderer's kernels are not compiled yet)\n" in got.out
    assert "\nsort auto -> exact (llvmpipe: software)\n" in got.out
    assert "\nearly-stop auto -> by coverage (llvmpipe: software)\n" in got.out
    assert got.err.count("the cpu renderer's kernels are compiling in a background process") == 1
    got = _render(tmp_path, capsys)                       # once a process
    assert "kernels" not in got.err


def test_timings_on_a_hardware_class_take_the_device_order_and_early_stop_on(unpinned, tmp_path,
                                                                             capsys):
    unpinned.setenv(device_class.CLASS_ENV, "hardware")
    out = _render(tmp_path, capsys).out
    assert "\nsort auto -> gpu (llvmpipe: hardware)\n" in out
    assert "\nearly-stop auto -> on (llvmpipe: hardware)\n" in out
    assert "renderer auto -> quad (" in out


def test_a_given_option_is_not_an_auto_choice(unpinned, tmp_path, capsys):
    unpinned.setenv(device_class.CLASS_ENV, "software")
    _ready(unpinned, True)
    out = _render(tmp_path, capsys, "--renderer", "quad", "--sort", "exact", "--early-stop", "off").out
    assert "auto ->" not in out


def test_render_auto_draws_with_the_cpu_renderer_where_its_kernels_are_ready(unpinned, tmp_path,
                                                                             capsys):
    pytest.importorskip("numba")
    unpinned.setenv(device_class.CLASS_ENV, "software")
    _ready(unpinned, True)
    out = _render(tmp_path, capsys).out
    assert "(32x24, 1604 splats, cpu)" in out and "renderer auto -> cpu (" in out
    out = _render(tmp_path, capsys, "--extent", "square").out      # a quad-only option
    assert "(32x24, 1604 splats, quad)" in out


def test_the_quad_renderer_batches_by_auto_as_the_device_class_says(unpinned):
    from splatgl.api import Renderer

    scene = random_scene(8)
    for cls, mode in (("hardware", EarlyStop.ON), ("software", EarlyStop.AUTO)):
        unpinned.setenv(device_class.CLASS_ENV, cls)
        with Renderer() as renderer:
            quad = renderer.renderer_for(scene, RenderSettings(), RendererKind.QUAD)
            assert quad.batches.mode is mode


def test_the_viewer_panel_names_the_sort_that_ran(ctx):
    from splatgl.cameras.camera import Camera
    from splatgl.viewer.display import Display
    from splatgl.viewer.modes import ViewMode

    display = Display(ctx)
    try:
        status = display.status(random_scene(8), RenderSettings(sort_key=resolve_sort("auto", HARDWARE)),
                                RendererKind.QUAD, ViewMode.COLOR, Camera.from_fov(32, 24, 60.0),
                                "fov 60", "", False)
    finally:
        display.release()
    assert status.settings == "rgba32f  SH 0/0  ellipse  sort gpu  bg 0,0,0"


def test_compiled_in_the_background_once_and_then_told(unpinned):
    import threading

    calls = []
    unpinned.setattr(cpu, "prepare", lambda progress=None: calls.append("prepare"))
    unpinned.setattr(auto, "_compiling", None)
    unpinned.setattr(auto, "_compiled", threading.Event())
    unpinned.setattr(auto, "_when_compiled", [])
    auto.compile_in_background().join()
    auto.compile_in_background().join()                   # once a process
    auto.when_compiled(lambda: calls.append("told"))      # ready already: told now
    assert calls == ["prepare", "told"]


def test_an_unclear_renderer_name_is_measured_once(unpinned, ctx):
    """A GL_RENDERER naming neither a software rasteriser nor a GPU vendor: the one-off probe
    (the radix sort against the CPU sort on the context) decides; on llvmpipe the CPU wins."""
    unpinned.setattr(device_class, "_MEASURED", {})
    assert classify("virgl (a host's GPU, or not)", ctx).cls is DeviceClass.SOFTWARE
    assert device_class._MEASURED == {"virgl (a host's GPU, or not)": DeviceClass.SOFTWARE}
    assert classify("virgl (a host's GPU, or not)", ctx).cls is DeviceClass.SOFTWARE  # cached
    assert classify("NVIDIA GeForce RTX 4090/PCIe/SSE2", ctx).cls is DeviceClass.HARDWARE
    assert len(device_class._MEASURED) == 1                      # a vendor's name: no probe


def test_the_apis_default_settings_take_the_devices_sort(unpinned):
    from splatgl.api import default_settings

    unpinned.setenv(device_class.CLASS_ENV, "hardware")
    assert default_settings().sort_key is SortKey.GPU
    assert default_settings(sort_key="exact").sort_key is SortKey.EXACT
    unpinned.setenv(device_class.CLASS_ENV, "software")
    assert default_settings(sort_key="auto").sort_key is SortKey.EXACT


def test_a_one_shot_render_compiles_the_kernels_once_in_a_process_of_its_own(unpinned, spawned,
                                                                             tmp_path, capsys):
    """The first ``render`` without the kernels draws with quad and starts their compile in a
    detached process; later commands while its stamp is fresh start none and say how it stands;
    a stale stamp (a compile that died) lets the next command start one again."""
    import os
    import sys

    unpinned.setenv(device_class.CLASS_ENV, "software")
    _ready(unpinned, False)
    got = _render(tmp_path, capsys)
    assert "(32x24, 1604 splats, quad)" in got.out
    assert got.err == ("splatgl: the cpu renderer's kernels are compiling in a background process "
                       "(first use, about half a minute, once); this command draws with quad\n")
    stamp = kernel_build.stamp_path()
    assert stamp.parent == tmp_path / "cache" / "splatgl" and stamp.read_text() == "compiling\n"
    [(argv, kwargs)] = spawned
    assert argv == [sys.executable, "-m", "splatgl.renderers.kernel_build", str(stamp)]
    assert kwargs["start_new_session"] and kwargs["stdin"] == kernel_build.subprocess.DEVNULL

    def again() -> str:
        unpinned.setattr(auto, "_told", False)            # a new process
        return _render(tmp_path, capsys).err

    assert "are still compiling in a background process (started 0 s ago)" in again()
    stamp.write_text("failed: no LLVM here\n")
    assert again() == ("splatgl: the cpu renderer's kernels did not compile (no LLVM here); "
                       "drawing with quad ('--renderer cpu' compiles them in the foreground)\n")
    stamp.write_text("ready\n")                           # done, yet numba's cache lacks them
    assert "were compiled 0 s ago, but numba's cache does not hold them now" in again()
    assert len(spawned) == 1
    old = stamp.stat().st_mtime - kernel_build.STALE_S - 1
    os.utime(stamp, (old, old))
    assert "are compiling in a background process (first use" in again()
    assert len(spawned) == 2 and stamp.read_text() == "compiling\n"


def test_without_a_writable_cache_folder_it_says_how_to_compile_them(unpinned, spawned, tmp_path,
                                                                     capsys):
    (tmp_path / "cache").write_text("a file where the folder would be")
    _ready(unpinned, False)
    auto.compiling_notice(auto.choose(device=SOFTWARE), background=False, detach=True)
    assert "'--renderer cpu' compiles them); drawing with quad this time" in capsys.readouterr().err
    assert spawned == []


def test_without_a_home_folder_nothing_is_written_in_the_working_one(unpinned, spawned, tmp_path,
                                                                    capsys):
    unpinned.setenv("XDG_CACHE_HOME", "relative/cache")
    unpinned.chdir(tmp_path)
    assert kernel_build.stamp_path() is None and kernel_build.start() is None
    assert list(tmp_path.iterdir()) == [] and spawned == []


def test_each_python_environment_has_its_own_stamp(unpinned, spawned):
    """Two virtual environments with the same versions keep two numba caches: one's compile
    says nothing of the other's."""
    import sys

    here = kernel_build.stamp_path()
    unpinned.setattr(sys, "prefix", sys.prefix + "-other")
    there = kernel_build.stamp_path()
    assert here.parent == there.parent and here != there


def test_a_benchmark_starts_no_compile_beside_its_timings(unpinned, spawned, capsys):
    _ready(unpinned, False)
    auto.compiling_notice(auto.choose(device=SOFTWARE), background=False)
    assert "not compiled yet" in capsys.readouterr().err and spawned == []


def test_the_compile_process_says_in_its_stamp_how_it_ended(monkeypatch, tmp_path):
    stamp = tmp_path / "stamp"

    def broken(progress=None):
        raise RuntimeError("LLVM ERROR: no target\nmore lines")

    monkeypatch.setattr(cpu, "prepare", broken)
    assert kernel_build.main([str(stamp)]) == 1
    assert stamp.read_text() == "failed: LLVM ERROR: no target\n"
    assert kernel_build.read(stamp).why == "LLVM ERROR: no target"
    monkeypatch.setattr(cpu, "prepare", lambda progress=None: None)
    assert kernel_build.main([str(stamp)]) == 0 and kernel_build.read(stamp).state == "ready"
    assert kernel_build.main([]) == 2
    stamp.write_text("something else\n")
    assert kernel_build.read(stamp) is None


def test_a_compile_whose_process_is_gone_lets_the_next_command_start_again(monkeypatch,
                                                                            tmp_path):
    """The child names itself (host, pid) in its stamp while it compiles; a ``compiling``
    stamp whose process no longer runs on this host (killed, a reboot) is not fresh, however
    young, so the next command need not wait ten minutes; one naming a live process, or
    another host's (which cannot be asked), still holds a new compile back."""
    import os
    import socket
    import subprocess
    import sys

    stamp = tmp_path / "stamp"
    seen = []

    def compile_(progress=None):
        seen.append(kernel_build.read(stamp))

    monkeypatch.setattr(cpu, "prepare", compile_)
    assert kernel_build.main([str(stamp)]) == 0
    [during] = seen
    assert (during.state, during.why) == ("compiling", f"{socket.gethostname()} {os.getpid()}")
    assert during.fresh and not during.gone
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stamp.write_text(f"compiling: {socket.gethostname()} {dead.pid}\n")
    build = kernel_build.read(stamp)
    assert build.age < kernel_build.STALE_S and build.gone and not build.fresh
    stamp.write_text(f"compiling: another-host {dead.pid}\n")
    assert kernel_build.read(stamp).fresh
    stamp.write_text("compiling\n")                      # as the parent writes it, no pid yet
    assert kernel_build.read(stamp).fresh


def test_the_compile_process_fills_numbas_cache(monkeypatch, tmp_path):
    """The real child, as :func:`kernel_build.start` runs it (``-m``, niced): afterwards
    ``kernels_ready`` finds every kernel in numba's on-disk cache (a compile of about half a
    minute where the cache was cold; a load where the suite's CPU renderer tests filled it)."""
    import subprocess
    import sys

    pytest.importorskip("numba")
    stamp = tmp_path / "stamp"
    done = subprocess.run([sys.executable, "-m", "splatgl.renderers.kernel_build", str(stamp)],
                          capture_output=True, text=True, timeout=600)
    assert (done.returncode, stamp.read_text()) == (0, "ready\n"), done.stderr
    monkeypatch.setattr(cpu, "_READY", False)
    assert cpu.kernels_ready()
