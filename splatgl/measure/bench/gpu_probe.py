"""Which OpenGL device splatgl renders on, checked: the first step of ``benchmarks/gpu_check.sh``.

``python -m splatgl.commands._bench_tools gpu-probe --out machine.json`` (its options:
:func:`splatgl.commands._bench_tools.gpu_probe_main`) makes a headless context the way every
command does (:func:`splatgl.gl.context.create_headless_context`: a hardware EGL device first,
``$SPLATGL_EGL_DEVICE`` overriding), prints the machine line and the GL renderer, vendor and
version, and writes them with the EGL device list and the EGL vendor files to ``--out``.  It
exits 1 with one line saying what to check when the renderer is a software rasteriser
(llvmpipe, softpipe, ...), unless ``--allow-software`` (for trying the check without a GPU).
"""

from __future__ import annotations

import glob
import platform

#: Where glvnd looks for EGL vendor files (the NVIDIA driver's is ``10_nvidia.json``).
EGL_VENDOR_DIRS = ("/usr/share/glvnd/egl_vendor.d", "/etc/glvnd/egl_vendor.d")
#: What to check when EGL gives a software renderer on a machine with an NVIDIA GPU.
SOFTWARE_HINT = ("check that the NVIDIA EGL vendor file (10_nvidia.json in "
                 + " or ".join(EGL_VENDOR_DIRS) + ") and libEGL_nvidia are installed (in a "
                 "container: NVIDIA_DRIVER_CAPABILITIES=graphics,compute,utility or all); "
                 "SPLATGL_EGL_DEVICE=N picks an EGL device")


def probe(commit: str | None = None) -> dict:
    """The machine (:func:`splatgl.measure.bench.machine.machine_info`), the GL strings, the EGL devices
    and vendor files, and the software versions, as one JSON-ready dict.  Raises
    :class:`splatgl.errors.ContextError` where no context can be made."""
    import moderngl
    import numpy

    from ... import __version__
    from ...gl.context import create_headless_context, renderer_name
    from ...gl.egl_devices import describe_devices, is_software_renderer, query_devices
    from .machine import machine_info

    devices = query_devices()
    ctx = create_headless_context()
    try:
        info = dict(ctx.info)
        name = renderer_name(ctx)
        extra = ctx.extra if isinstance(ctx.extra, dict) else {}
        version = ctx.version_code
    finally:
        ctx.release()
    vendor_files = sorted(f for d in EGL_VENDOR_DIRS for f in glob.glob(f"{d}/*.json"))
    return {
        "machine": machine_info(name),
        "gl": {"renderer": info.get("GL_RENDERER", "?"), "vendor": info.get("GL_VENDOR", "?"),
               "version": info.get("GL_VERSION", "?"), "version_code": version,
               "software": is_software_renderer(info.get("GL_RENDERER", "")),
               "egl_device": extra.get("egl_device"),
               "egl_skipped": extra.get("egl_skipped", []),
               "backend": "osmesa" if "osmesa_loader" in extra else "egl"},
        "egl_device_list": describe_devices(devices),
        "egl_devices": None if devices is None else [
            {"index": d.index, "software": d.software, "drm_file": d.drm_file,
             "extensions": sorted(d.extensions)} for d in devices],
        "egl_vendor_files": vendor_files,
        "versions": {"splatgl": __version__, "python": platform.python_version(),
                     "numpy": numpy.__version__, "moderngl": moderngl.__version__},
        "commit": commit,
    }
