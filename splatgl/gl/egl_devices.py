"""Which EGL device a headless context runs on: a hardware one first.

``EGL_EXT_device_enumeration`` lists the devices of every installed EGL vendor (through
glvnd): on a machine with an NVIDIA GPU and Mesa, the NVIDIA device(s) and Mesa's software
device (llvmpipe), in an order the vendors decide.  moderngl's EGL backend (glcontext) opens
device 0 unless given ``device_index``, so a machine with a GPU may silently render on
llvmpipe.  :func:`query_devices` lists the devices through ctypes over libEGL (no context is
made); a device whose extensions include ``EGL_MESA_device_software`` is software.
:func:`candidate_order` puts hardware devices first; ``$SPLATGL_EGL_DEVICE=N`` overrides the
choice (:func:`parse_override`).  The context itself is made in :mod:`splatgl.gl.context`.
"""

from __future__ import annotations

import ctypes
import ctypes.util
from dataclasses import dataclass
from typing import Sequence

from ..errors import ContextError

#: The environment variable that names the EGL device to use (an index into EGL's list).
DEVICE_ENV = "SPLATGL_EGL_DEVICE"
#: glcontext's own device variable: glcontext obeys it over any index splatgl passes.
GLCONTEXT_DEVICE_ENV = "GLCONTEXT_DEVICE_INDEX"
#: The device extension Mesa gives its software (llvmpipe / softpipe) device.
SOFTWARE_EXTENSION = "EGL_MESA_device_software"
#: Words in a GL_RENDERER string that mean a software rasteriser (compared in lower case).
SOFTWARE_RENDERER_WORDS = ("llvmpipe", "softpipe", "swrast", "software", "swiftshader")

# EGL constants (EGL/egl.h, EGL/eglext.h).
_EGL_EXTENSIONS = 0x3055
_EGL_DRM_DEVICE_FILE_EXT = 0x3233
_EGL_DRM_RENDER_NODE_FILE_EXT = 0x3377


@dataclass(frozen=True)
class EglDevice:
    """One entry of EGL's device list: its index (what glcontext's ``device_index`` takes),
    its device extensions and, where the driver says, its DRM device file."""

    index: int
    extensions: frozenset[str]
    drm_file: str | None = None

    @property
    def software(self) -> bool:
        return SOFTWARE_EXTENSION in self.extensions

    def describe(self) -> str:
        """``1 hardware (/dev/dri/renderD128)`` or ``0 software``."""
        where = f" ({self.drm_file})" if self.drm_file else ""
        return f"{self.index} {'software' if self.software else 'hardware'}{where}"


def is_software_renderer(gl_renderer: str) -> bool:
    """Whether a GL_RENDERER string names a software rasteriser (llvmpipe, softpipe, ...)."""
    name = gl_renderer.lower()
    return any(word in name for word in SOFTWARE_RENDERER_WORDS)


def query_devices() -> list[EglDevice] | None:
    """EGL's devices in EGL's order, or ``None`` where libEGL or device enumeration is missing
    (then only glcontext's default device can be used)."""
    name = ctypes.util.find_library("EGL")
    if name is None:
        return None
    try:
        lib = ctypes.CDLL(name)
        lib.eglQueryString.restype = ctypes.c_char_p
        lib.eglQueryString.argtypes = [ctypes.c_void_p, ctypes.c_int]
        lib.eglGetProcAddress.restype = ctypes.c_void_p
        lib.eglGetProcAddress.argtypes = [ctypes.c_char_p]
    except (OSError, AttributeError):
        return None
    client = (lib.eglQueryString(None, _EGL_EXTENSIONS) or b"").decode(errors="replace").split()
    if "EGL_EXT_device_enumeration" not in client and "EGL_EXT_device_base" not in client:
        return None
    query_addr = lib.eglGetProcAddress(b"eglQueryDevicesEXT")
    string_addr = lib.eglGetProcAddress(b"eglQueryDeviceStringEXT")
    if not query_addr or not string_addr:
        return None
    query = ctypes.CFUNCTYPE(ctypes.c_uint, ctypes.c_int, ctypes.POINTER(ctypes.c_void_p),
                             ctypes.POINTER(ctypes.c_int))(query_addr)
    string = ctypes.CFUNCTYPE(ctypes.c_char_p, ctypes.c_void_p, ctypes.c_int)(string_addr)
    count = ctypes.c_int(0)
    if not query(0, None, ctypes.byref(count)) or count.value <= 0:
        return None
    handles = (ctypes.c_void_p * count.value)()
    if not query(count.value, handles, ctypes.byref(count)):
        return None
    devices = []
    for i in range(count.value):
        exts = frozenset((string(handles[i], _EGL_EXTENSIONS) or b"").decode(errors="replace").split())
        drm = None
        for ext, attr in (("EGL_EXT_device_drm_render_node", _EGL_DRM_RENDER_NODE_FILE_EXT),
                          ("EGL_EXT_device_drm", _EGL_DRM_DEVICE_FILE_EXT)):
            if drm is None and ext in exts:
                value = string(handles[i], attr)
                drm = value.decode(errors="replace") if value else None
        devices.append(EglDevice(i, exts, drm))
    return devices


def describe_devices(devices: Sequence[EglDevice] | None) -> str:
    """``EGL devices: 0 hardware (/dev/dri/renderD128), 1 software`` (one line)."""
    if devices is None:
        return "EGL device enumeration unavailable"
    if not devices:
        return "no EGL devices"
    return "EGL devices: " + ", ".join(d.describe() for d in devices)


def candidate_order(devices: Sequence[EglDevice]) -> list[int]:
    """Device indices to try: hardware devices in EGL's order, then software ones."""
    return ([d.index for d in devices if not d.software]
            + [d.index for d in devices if d.software])


def override_text(environ) -> str | None:
    """The device index the user asked for (``$SPLATGL_EGL_DEVICE``, else glcontext's own
    ``$GLCONTEXT_DEVICE_INDEX``), as given, or ``None``.  Raises :class:`ContextError` when both
    are set and differ (glcontext would obey its own)."""
    ours = (environ.get(DEVICE_ENV) or "").strip()
    theirs = (environ.get(GLCONTEXT_DEVICE_ENV) or "").strip()
    if ours and theirs and ours != theirs:
        raise ContextError(f"{DEVICE_ENV}={ours} and {GLCONTEXT_DEVICE_ENV}={theirs} disagree "
                           f"(glcontext obeys {GLCONTEXT_DEVICE_ENV}); unset one")
    return ours or theirs or None


def parse_override(text: str, devices: Sequence[EglDevice] | None) -> int:
    """The device index ``text`` (from ``$SPLATGL_EGL_DEVICE``) names, checked against
    ``devices`` where EGL listed them.  Raises :class:`ContextError` in one line, with the
    devices there are, when it is not an index of one."""
    try:
        index = int(text)
    except ValueError:
        index = -1
    if index < 0 or (devices is not None and index >= len(devices)):
        raise ContextError(f"{DEVICE_ENV}={text}: no such EGL device; {describe_devices(devices)}")
    return index
