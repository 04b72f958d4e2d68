"""The machine a benchmark ran on: CPU model, SIMD level, cores, OpenGL renderer.

Figures from one machine do not carry over to another (NumPy's sort alone is several times
faster with AVX-512 than with AVX2; llvmpipe's speed follows the cores), so every result names
its machine and published figures are ratios from one run.
"""

from __future__ import annotations

import os
import platform
from pathlib import Path

#: SIMD levels from best to worst, each with the /proc/cpuinfo flags that define it.
SIMD_LEVELS = (("avx512", ("avx512f",)), ("avx2", ("avx2",)), ("avx", ("avx",)),
               ("sse4.2", ("sse4_2",)), ("neon", ("neon", "asimd")))


def _cpuinfo(text: str | None = None) -> tuple[str, set[str]]:
    """(CPU model name, flag set) from /proc/cpuinfo text (read when None)."""
    if text is None:
        try:
            text = Path("/proc/cpuinfo").read_text(errors="replace")
        except OSError:
            text = ""
    model, flags = "", set()
    for line in text.splitlines():
        key, _, value = line.partition(":")
        key = key.strip().lower()
        if key in ("model name", "hardware", "cpu model") and not model:
            model = value.strip()
        elif key in ("flags", "features") and not flags:
            flags = set(value.split())
    return model, flags


def simd_level(flags: set[str]) -> str:
    """The best SIMD level the flags show: avx512, avx2, avx, sse4.2, neon, or "unknown"."""
    for level, needs in SIMD_LEVELS:
        if any(f in flags for f in needs):
            return level
    return "unknown"


#: The GL renderer field of benchmarks that make no OpenGL context (CPU stages alone).
CPU_ONLY = "none (CPU only)"


def machine_info(gl_renderer: str | None = None, cpuinfo_text: str | None = None,
                 default_row=None) -> dict:
    """``{"cpu", "simd", "cores", "gl_renderer", "platform"}`` of this machine.

    ``cores`` counts the CPUs this process may run on (its affinity), which is what NumPy's
    threads and llvmpipe get.  ``default_row``: the settings of the scene benchmark's default
    row (a RenderSettings), whose sort (``--sort auto`` on this device) is then ``"default_sort"``.
    """
    model, flags = _cpuinfo(cpuinfo_text)
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cores = os.cpu_count() or 1
    from ...order import kernels as cull_kernel

    return {"cpu": model or platform.processor() or platform.machine() or "?",
            "simd": simd_level(flags), "cores": cores,
            "gl_renderer": gl_renderer or "?", "platform": platform.platform(terse=True),
            "cull": "compiled (numba)" if cull_kernel.installed() else "numpy",
            **(auto_choices(gl_renderer) if gl_renderer else {}),
            **({"default_sort": default_row.sort_key.value} if default_row is not None else {})}


def auto_choices(gl_renderer: str) -> dict:
    """What ``--sort auto`` and ``--early-stop auto`` take on this GL renderer's device
    (:mod:`splatgl.gl.device_class`): ``{"device_class", "sort_auto", "early_stop_auto"}``."""
    from ...gl.device_class import AUTO, classify, resolve_early_stop, resolve_sort

    device = classify(gl_renderer)
    stop = resolve_early_stop(AUTO, device).value
    return {"device_class": device.cls.value, "sort_auto": resolve_sort(AUTO, device).value,
            "early_stop_auto": "by coverage" if stop == AUTO else stop}


def probe_machine() -> dict:
    """:func:`machine_info` with the GL renderer of a headless context made (and released) for
    the purpose, as every benchmark gets it (:func:`splatgl.gl.context.renderer_name`)."""
    from ...gl.context import create_headless_context, renderer_name

    ctx = create_headless_context()
    try:
        return machine_info(renderer_name(ctx))
    finally:
        ctx.release()


def describe(info: dict) -> str:
    """One line: ``machine: AMD EPYC (avx2), 2 cores, GL renderer llvmpipe (...), cull numpy``
    (the cull path matters to the cull figures: the compiled one where numba is installed)."""
    return (f"machine: {info['cpu']} ({info['simd']}), {info['cores']} cores, "
            f"GL renderer {info['gl_renderer']}, cull {info.get('cull', '?')}"
            + (f", {info['device_class']} device: sort auto -> {info['sort_auto']}, early-stop "
               f"auto -> {info['early_stop_auto']}" if "device_class" in info else "")
            + (f"; the default row: sort {info['default_sort']}" if "default_sort" in info else ""))
