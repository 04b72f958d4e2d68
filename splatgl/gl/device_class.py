"""What the OpenGL device is (a hardware GPU or a software rasteriser), and the defaults that
follow from it: ``--sort auto`` and ``--early-stop auto`` (issue 40 item 4).

One place decides the class, from what the device says it is:

- ``SPLATGL_DEVICE_CLASS=software|hardware`` forces it (tests; a machine whose driver
  misnames itself);
- a context's ``GL_RENDERER``: llvmpipe, softpipe, swrast, "Software" or SwiftShader is
  software (:func:`splatgl.gl.egl_devices.is_software_renderer`), anything else hardware;
- without a context (:func:`expected`): EGL's device list, which
  :func:`splatgl.gl.context.create_headless_context` also reads: a hardware device there is
  what a context gets first, so the class is hardware; software devices only, software.  Where
  EGL lists no devices (no enumeration extension, OSMesa) the list cannot say: a context is
  made once, its ``GL_RENDERER`` read and the context released.
- a ``GL_RENDERER`` that names neither a software rasteriser nor a GPU vendor (virgl, a
  d3d12 or zink layer) is measured once (:func:`measured`: the radix sort against the CPU
  sort on the context).

The defaults, by measurement:

- sort: software -> ``exact`` (the CPU order; llvmpipe sorts 1M keys on the CPU faster than
  its compute shaders do, ``splatgl bench --scale``); hardware -> ``gpu`` (the device-resident
  order: on the H100 the CPU cull, sort and upload were 126 of 275 ms at 6M, docs/gpu.md).
- early termination: software keeps the coverage rule tuned on llvmpipe (``auto``);
  hardware -> ``on`` (on one H100, guitar 320x180: 1.30x faster than off, while the llvmpipe
  rule chose the plain draw; docs/gpu.md).  Measured on one GPU only.
"""

from __future__ import annotations

import enum
import functools
import os
from dataclasses import dataclass

from ..errors import SplatglError
from ..scene.settings import EarlyStop, SortKey
from .egl_devices import DEVICE_ENV, is_software_renderer, query_devices

#: The environment variable that forces the device class.
CLASS_ENV = "SPLATGL_DEVICE_CLASS"
#: The value of ``--sort`` and ``--early-stop`` that this module resolves.
AUTO = "auto"


class DeviceClass(enum.Enum):
    SOFTWARE = "software"
    HARDWARE = "hardware"


@dataclass(frozen=True)
class Device:
    """The class of the device and how it is named in messages ("llvmpipe", "NVIDIA H100 ...")."""

    cls: DeviceClass
    name: str

    @property
    def software(self) -> bool:
        return self.cls is DeviceClass.SOFTWARE

    def label(self) -> str:
        """``llvmpipe: software``: what ``--timings`` shows in parentheses after a choice."""
        return f"{self.name}: {self.cls.value}"


def forced() -> DeviceClass | None:
    """The class ``SPLATGL_DEVICE_CLASS`` forces, or None; a bad value is one line."""
    text = os.environ.get(CLASS_ENV, "").strip().lower()
    if not text:
        return None
    try:
        return DeviceClass(text)
    except ValueError:
        raise SplatglError(f"{CLASS_ENV}={text}: must be 'software' or 'hardware'") from None


def short_name(gl_renderer: str) -> str:
    """``llvmpipe`` from ``llvmpipe (LLVM 15.0.7, 256 bits)``; ``NVIDIA H100 80GB HBM3`` from
    ``NVIDIA H100 80GB HBM3/PCIe/SSE2``: the GL renderer's name without its details."""
    return gl_renderer.split(" (")[0].split("/")[0].strip() or gl_renderer


#: Words of a GL_RENDERER string that name a GPU vendor (lower case): a name with none of
#: these and none of the software words is unclear, and a context's device is then measured.
HARDWARE_WORDS = ("nvidia", "geforce", "quadro", "tesla", "radeon", "amd", "intel", "iris",
                  "apple", "mali", "adreno", "powervr", "immortalis")
#: Keys the measured probe sorts, on the CPU and with the compute radix sort.
PROBE_KEYS = 1 << 18


def classify(gl_renderer: str, ctx=None) -> Device:
    """The device behind a ``GL_RENDERER`` string (``SPLATGL_DEVICE_CLASS`` first); a name
    that says neither (virgl, a d3d12 or zink layer) is measured on ``ctx`` where given
    (:func:`measured`), taken as hardware otherwise."""
    cls = forced()
    if cls is None and is_software_renderer(gl_renderer):
        cls = DeviceClass.SOFTWARE
    elif cls is None and ctx is not None and not any(w in gl_renderer.lower()
                                                     for w in HARDWARE_WORDS):
        cls = measured(gl_renderer, ctx)
    return Device(cls or DeviceClass.HARDWARE, short_name(gl_renderer))


def of_context(ctx) -> Device:
    """The device a context draws on (its ``GL_RENDERER``; measured where unclear)."""
    from .context import renderer_name

    return classify(renderer_name(ctx), ctx)


_MEASURED: dict[str, DeviceClass] = {}


def measured(gl_renderer: str, ctx) -> DeviceClass:
    """The one-off probe, once per renderer name and process: :data:`PROBE_KEYS` depth keys
    sorted by the compute radix sort against the CPU sort (best of 3 each, after a warm-up);
    hardware where the device sorts faster, as on a GPU, software where the CPU does (llvmpipe
    sorts 3-4x slower than the CPU)."""
    if gl_renderer not in _MEASURED:
        import time

        import numpy as np

        from ..order.sort import depth_sort
        from .radix_sort import RadixSorter

        rng = np.random.default_rng(0)
        depth = rng.uniform(0.5, 50.0, PROBE_KEYS).astype(np.float32)
        keys, rows = depth.view(np.uint32), np.arange(PROBE_KEYS, dtype=np.uint32)
        sorter = RadixSorter(ctx)
        try:
            def best(run) -> float:
                run()
                times = []
                for _ in range(3):
                    t0 = time.perf_counter()
                    run()
                    times.append(time.perf_counter() - t0)
                return min(times)

            device = best(lambda: sorter.sort_values(keys, rows))
            cpu = best(lambda: depth_sort(depth, rows))
        finally:
            sorter.release()
        _MEASURED[gl_renderer] = DeviceClass.HARDWARE if device < cpu else DeviceClass.SOFTWARE
    return _MEASURED[gl_renderer]


def expected() -> Device:
    """The device a headless context of this process would get, without making one where EGL's
    device list says (see the module doc); cached for the process."""
    cls = forced()
    device = _listed()
    if cls is not None:
        return Device(cls, device.name if device is not None else "forced")
    return device if device is not None else _probed()


@functools.lru_cache(maxsize=1)
def _listed() -> Device | None:
    devices = query_devices()
    if not devices:
        return None
    named = os.environ.get(DEVICE_ENV, "").strip()
    if named.isdigit() and int(named) < len(devices):   # SPLATGL_EGL_DEVICE=N: that one
        devices = [devices[int(named)]]
    hardware = [d for d in devices if not d.software]
    if hardware:
        return Device(DeviceClass.HARDWARE, f"EGL device {hardware[0].index}")
    return Device(DeviceClass.SOFTWARE, "software EGL device")


@functools.lru_cache(maxsize=1)
def _probed() -> Device:
    from .context import create_headless_context

    try:
        ctx = create_headless_context()
    except SplatglError as exc:      # no OpenGL here: whatever draws is the CPU
        return Device(DeviceClass.SOFTWARE, f"no OpenGL context: {exc}".split(";")[0])
    try:
        return of_context(ctx)
    finally:
        ctx.release()


def resolve_sort(value: SortKey | str, device: Device | None = None) -> SortKey:
    """``--sort``'s value: ``auto`` -> ``gpu`` on hardware, ``exact`` on software; others as given."""
    if value != AUTO:
        return SortKey(value)
    device = device or expected()
    return SortKey.EXACT if device.software else SortKey.GPU


def resolve_early_stop(mode: EarlyStop | str, device: Device) -> EarlyStop:
    """Early termination on ``device``: ``auto`` is ``on`` on hardware (measured on one H100),
    the coverage rule tuned on llvmpipe (``auto``) on software; ``on`` and ``off`` as given."""
    mode = EarlyStop(mode)
    if mode is EarlyStop.AUTO and not device.software:
        return EarlyStop.ON
    return mode


def choice_text(option: str, chosen: str, device: Device) -> str:
    """``sort auto -> exact (llvmpipe: software)``: what ``--timings``, the bench's machine line
    and the viewer print for an ``auto`` option."""
    return f"{option} auto -> {chosen} ({device.label()})"
