"""Which OpenGL device splatgl renders on, checked: the first step of ``benchmarks/gpu_check.sh``.

``python -m splatgl.bench.gpu_probe --out machine.json`` makes a headless context the way every
command does (:func:`splatgl.gl.context.create_headless_context`: a hardware EGL device first,
``$SPLATGL_EGL_DEVICE`` overriding), prints the machine line and the GL renderer, vendor and
version, and writes them with the EGL device list and the EGL vendor files to ``--out``.  It
exits 1 with one line saying what to check when the renderer is a software rasteriser
(llvmpipe, softpipe, ...), unless ``--allow-software`` (for trying the check without a GPU).
"""

from __future__ import annotations

import argparse
import glob
import json
import platform
import sys
from pathlib import Path

#: Where glvnd looks for EGL vendor files (the NVIDIA driver's is ``10_nvidia.json``).
EGL_VENDOR_DIRS = ("/usr/share/glvnd/egl_vendor.d", "/etc/glvnd/egl_vendor.d")
#: What to check when EGL gives a software renderer on a machine with an NVIDIA GPU.
SOFTWARE_HINT = ("check that the NVIDIA EGL vendor file (10_nvidia.json in "
                 + " or ".join(EGL_VENDOR_DIRS) + ") and libEGL_nvidia are installed (in a "
                 "container: NVIDIA_DRIVER_CAPABILITIES=graphics,compute,utility or all); "
                 "SPLATGL_EGL_DEVICE=N picks an EGL device")


def probe(commit: str | None = None) -> dict:
    """The machine (:func:`splatgl.bench.machine.machine_info`), the GL strings, the EGL devices
    and vendor files, and the software versions, as one JSON-ready dict.  Raises
    :class:`splatgl.errors.ContextError` where no context can be made."""
    import moderngl
    import numpy

    from .. import __version__
    from ..gl.context import create_headless_context, renderer_name
    from ..gl.egl_devices import describe_devices, is_software_renderer, query_devices
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


def main(argv: list[str] | None = None) -> int:
    from ..output.atomic import atomic_write_text
    from ..errors import SplatglError
    from .machine import describe

    p = argparse.ArgumentParser(prog="python -m splatgl.bench.gpu_probe", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", type=Path, default=None, help="write the JSON there (machine.json)")
    p.add_argument("--commit", default=None, help="the source revision, recorded as given")
    p.add_argument("--allow-software", action="store_true",
                   help="do not fail on a software renderer (trying the check without a GPU)")
    args = p.parse_args(argv)
    try:
        doc = probe(args.commit)
        if args.out is not None:
            atomic_write_text(args.out, json.dumps(doc, indent=1) + "\n")
    except SplatglError as exc:
        print(f"gpu_probe: error: {exc}", file=sys.stderr)
        return 2
    gl = doc["gl"]
    print(describe(doc["machine"]))
    print(f"GL renderer: {gl['renderer']}")
    print(f"GL vendor: {gl['vendor']}; GL version: {gl['version']}; "
          f"{doc['egl_device_list']}")
    for reason in gl["egl_skipped"]:
        print(f"EGL device skipped: {reason}")
    if gl["software"]:
        what = "allowed (--allow-software)" if args.allow_software else "error"
        print(f"gpu_probe: {what}: GL renderer '{gl['renderer']}' is a software rasteriser, "
              f"not the GPU; {SOFTWARE_HINT}", file=sys.stderr)
        return 0 if args.allow_software else 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
