"""``--renderer auto``: the fastest renderer of the exact frame on this device (issue 40 item 4).

On a machine without a GPU (a software OpenGL device, :mod:`splatgl.gl.device_class`) the CPU
renderer draws the exact frame about 3x sooner than llvmpipe's quads
(docs/results/cpu-renderer-avx2.json), so ``auto`` is the CPU renderer there when

- the registry says it can draw the request (:func:`splatgl.renderers.registry.refusal`: 3DGS
  splats, colour, alpha and depth, no geometry under them), with the options given: an option
  only the quad path reads, away from its default (``--precision``, ``--extent``,
  ``--sort gpu``, ``--early-stop``, ...), means the quad path;
- and its compiled kernels are ready (:func:`splatgl.renderers.cpu.kernels_ready`: numba's
  on-disk cache holds them).  A compile takes about 25 s on the 2-core AVX2 machine, a load
  from the cache about 0.5 s (:func:`splatgl.renderers.cpu.prepare`).

Otherwise, and on every hardware GPU, ``auto`` is the quad path.  Where only the missing
kernels stood in the way the caller says so once (:func:`compiling_notice`): the viewer
compiles them on a background thread (:func:`compile_in_background`), draws with the quad
path meanwhile and with the CPU renderer once they are ready (:func:`when_compiled`); a
one-shot ``render`` draws with the quad path rather than wait half a minute for a frame that
takes a second or two there, and starts the compile in a detached low-priority process
(:mod:`splatgl.renderers.kernel_build`), so that the next command finds them ready.

``SPLATGL_RENDERER_AUTO=quad`` pins ``auto`` to the quad path (the test suite sets it, so that
no test depends on whether numba's cache is warm; docs/testing.md).
"""

from __future__ import annotations

import os
import sys
import threading
from dataclasses import dataclass
from typing import Callable

from ..errors import SplatglError
from ..gl.device_class import Device, expected
from ..scene.settings import RendererKind, RenderSettings
from .registry import check_settings, refusal

#: The ``--renderer`` value this module resolves.
AUTO = "auto"
#: ``quad`` pins ``auto`` to the quad path (the test suite); unset: the device's rule.
PIN_ENV = "SPLATGL_RENDERER_AUTO"


@dataclass(frozen=True)
class Choice:
    """What ``auto`` chose, and why (``llvmpipe: software, cpu kernels ready``)."""

    kind: RendererKind
    why: str
    #: Only the CPU renderer's missing compiled kernels kept it from drawing.
    kernels_missing: bool = False

    def text(self) -> str:
        """``renderer auto -> cpu (llvmpipe: software, cpu kernels ready)``."""
        return f"renderer auto -> {self.kind.value} ({self.why})"


def choose(*, scene=None, settings: RenderSettings | None = None, model=None, layers=None,
           under: bool = False, device: Device | None = None) -> Choice:
    """The renderer ``--renderer auto`` draws this request with (see the module doc); what is
    not given is not checked."""
    pin = os.environ.get(PIN_ENV, "").strip().lower()
    if pin == "quad":
        return Choice(RendererKind.QUAD, f"{PIN_ENV}=quad")
    if pin:
        raise SplatglError(f"{PIN_ENV}={pin}: must be 'quad' or unset")
    device = device or expected()
    if not device.software:
        return Choice(RendererKind.QUAD, device.label())
    why = refusal(RendererKind.CPU, scene=scene, settings=settings, model=model, layers=layers,
                  under=under)
    if why is None and settings is not None:
        try:
            check_settings(settings, RendererKind.CPU)
        except SplatglError as exc:
            why = str(exc)
    if why is not None:
        return Choice(RendererKind.QUAD, f"{device.label()}; the cpu renderer: "
                      f"{why.split(' (use --renderer')[0]}")
    from .cpu import kernels_ready

    if not kernels_ready():
        return Choice(RendererKind.QUAD, f"{device.label()}; the cpu renderer's kernels are not "
                      "compiled yet", kernels_missing=True)
    return Choice(RendererKind.CPU, f"{device.label()}, cpu kernels ready")


_told = False


def compiling_notice(choice: Choice, background: bool, detach: bool = False) -> None:
    """Say once per process, on stderr, that the CPU renderer waits for its kernels:
    ``background``, that they are compiling now (the viewer, on a thread); ``detach`` (a
    one-shot command), start their compile in a process of its own
    (:func:`splatgl.renderers.kernel_build.start`) and say how it stands; else how to compile
    them (a benchmark: nothing may run beside its timings)."""
    global _told
    if _told or not choice.kernels_missing:
        return
    _told = True
    if background:
        line = ("the cpu renderer's kernels are compiling (first use, about half a minute, in "
                "the background); drawing with quad until they are ready")
    else:
        line = _detached_line() if detach else None
        line = line or ("the cpu renderer's kernels are not compiled yet (first use, about half "
                        "a minute once: '--renderer cpu' compiles them); drawing with quad this "
                        "time")
    print(f"splatgl: {line}", file=sys.stderr, flush=True)


def _detached_line() -> str | None:
    """Start the detached compile where none ran lately; what to say of it (None: it could not
    be started)."""
    from . import kernel_build

    build = kernel_build.start()
    if build is None:
        return None
    kernels = "the cpu renderer's kernels"
    if build.state == kernel_build.COMPILING and build.age == 0.0:
        return (f"{kernels} are compiling in a background process (first use, about half a "
                "minute, once); this command draws with quad")
    if build.state == kernel_build.COMPILING:
        return (f"{kernels} are still compiling in a background process (started "
                f"{build.age:.0f} s ago); this command draws with quad")
    if build.state == kernel_build.FAILED:
        return (f"{kernels} did not compile ({build.why}); drawing with quad ('--renderer cpu' "
                "compiles them in the foreground)")
    return (f"{kernels} were compiled {build.age:.0f} s ago, but numba's cache does not hold "
            "them now (is its folder writable?); drawing with quad ('--renderer cpu' compiles "
            "them in the foreground)")


_compiling: threading.Thread | None = None
_compiled = threading.Event()
_when_compiled: list[Callable[[], None]] = []


def _compile() -> None:
    from .cpu import prepare

    try:
        prepare(lambda *_: None)
    except Exception:   # noqa: BLE001 (a failed compile leaves the quad path drawing)
        return
    _compiled.set()
    for callback in list(_when_compiled):
        callback()


def compile_in_background() -> threading.Thread:
    """Compile (or load) the CPU renderer's kernels on a daemon thread, once per process;
    numba keeps them in its on-disk cache, so the next ``auto`` finds them ready."""
    global _compiling
    if _compiling is None:
        _compiling = threading.Thread(target=_compile, name="splatgl-cpu-kernels", daemon=True)
        _compiling.start()
    return _compiling


def when_compiled(callback: Callable[[], None]) -> None:
    """Call ``callback`` (on the compiling thread) once :func:`compile_in_background`'s kernels
    are ready, or now if they are: the viewer then draws its exact frame with them."""
    _when_compiled.append(callback)
    if _compiled.is_set():
        callback()
