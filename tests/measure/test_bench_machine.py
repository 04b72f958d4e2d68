"""The machine a benchmark ran on is recorded from /proc/cpuinfo and the GL context."""

from __future__ import annotations

import pytest

from splatgl.measure.bench.machine import describe, machine_info, simd_level

EPYC = """processor\t: 0
vendor_id\t: AuthenticAMD
model name\t: AMD EPYC 7B13
flags\t\t: fpu sse4_2 avx avx2 fma bmi2
"""
XEON = EPYC.replace("AMD EPYC 7B13", "Intel(R) Xeon(R) Platinum 8488C").replace(
    "avx2 fma", "avx2 avx512f avx512bw fma")


def test_simd_level_is_the_best_flag():
    assert simd_level({"sse4_2", "avx", "avx2"}) == "avx2"
    assert simd_level({"avx2", "avx512f"}) == "avx512"
    assert simd_level({"asimd"}) == "neon"
    assert simd_level(set()) == "unknown"


def test_machine_info_from_cpuinfo_text():
    info = machine_info("llvmpipe (LLVM 15.0.6, 256 bits)", EPYC)
    assert (info["cpu"], info["simd"], info["gl_renderer"]) == (
        "AMD EPYC 7B13", "avx2", "llvmpipe (LLVM 15.0.6, 256 bits)")
    assert info["cores"] >= 1
    assert machine_info("x", XEON)["simd"] == "avx512"
    from splatgl.order import kernels as cull_kernel

    cull = "compiled (numba)" if cull_kernel.installed() else "numpy"
    assert info["cull"] == cull
    assert describe(info) == (f"machine: AMD EPYC 7B13 (avx2), {info['cores']} cores, "
                              f"GL renderer llvmpipe (LLVM 15.0.6, 256 bits), cull {cull}, "
                              "software device: sort auto -> exact, early-stop auto -> by coverage")


def test_this_machine_is_described():
    info = machine_info()
    assert info["cpu"] and info["simd"] in ("avx512", "avx2", "avx", "sse4.2", "neon", "unknown")


def test_probe_machine_names_the_contexts_renderer():
    from splatgl.measure.bench.machine import probe_machine
    from splatgl.errors import ContextError
    from splatgl.gl.context import create_headless_context, renderer_name

    try:
        ctx = create_headless_context()
    except ContextError as exc:
        pytest.skip(f"no OpenGL: {exc}")
    name = renderer_name(ctx)
    ctx.release()
    info = probe_machine()
    assert info["gl_renderer"] == name and name not in ("", "?")
    assert f"GL renderer {name}, cull" in describe(info)


def test_machine_line_says_what_auto_takes_on_a_gpu(monkeypatch):
    """Issue 40 item 4: the bench's machine line names the device class and what --sort auto
    and --early-stop auto take there."""
    monkeypatch.delenv("SPLATGL_DEVICE_CLASS", raising=False)
    info = machine_info("NVIDIA H100 80GB HBM3/PCIe/SSE2", XEON)
    assert (info["device_class"], info["sort_auto"], info["early_stop_auto"]) == (
        "hardware", "gpu", "on")
    assert describe(info).endswith(", hardware device: sort auto -> gpu, early-stop auto -> on")


@pytest.mark.parametrize("device_class, sort", [("hardware", "gpu"), ("software", "exact")])
def test_the_default_row_draws_what_render_draws_on_the_device(ctx, monkeypatch, device_class, sort):
    """Issue 40 item 4: the scene benchmark's default row measured the exact CPU sort on every
    device while render's --sort auto takes the GPU sort on hardware: it now takes --sort auto's
    choice for its context's device (and the savings rows with it), and the machine line says
    which ran."""
    from splatgl.measure.bench import scene_task
    from splatgl.measure.bench.runner import BenchOptions

    monkeypatch.setenv("SPLATGL_DEVICE_CLASS", device_class)
    seen = {}
    monkeypatch.setattr(scene_task, "bench_scene",
                        lambda r, name, s, o, base, progress=None: seen.setdefault("rows", base) and [])
    monkeypatch.setattr("splatgl.measure.bench.savings.savings_rows",
                        lambda r, name, s, o, base: seen.setdefault("savings", base) and [])

    class _Renderer:
        pass

    renderer = _Renderer()
    renderer.ctx = ctx
    scene_task.measure_scene(renderer, scene_task.SceneSpec("x", synthetic=10), None,
                             BenchOptions(8, 8, 1), savings=True)
    assert seen["rows"].sort_key.value == seen["savings"].sort_key.value == sort
    assert scene_task.default_base(ctx).sort_key.value == sort
    info = machine_info("llvmpipe (LLVM 15.0.6, 256 bits)", EPYC, default_row=scene_task.default_base(ctx))
    assert describe(info).endswith(f"early-stop auto -> {'on' if sort == 'gpu' else 'by coverage'}; "
                                   f"the default row: sort {sort}")
