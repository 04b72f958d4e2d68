"""The one place that creates OpenGL contexts.

Headless: EGL through moderngl (``backend='egl'``, works with or without DISPLAY), falling back to
OSMesa through ctypes (``libOSMesa``, Debian ``libosmesa6``) where EGL is missing.  The
environment variable ``SPLATGL_GL_BACKEND`` (``egl`` or ``osmesa``) forces one.  Where EGL lists
several devices (a GPU beside Mesa's llvmpipe), a hardware one is used first;
``SPLATGL_EGL_DEVICE=N`` picks device N (:mod:`splatgl.gl.egl_devices`).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import enum
import os
from contextlib import contextmanager

import moderngl

from ..errors import ContextError
from . import egl_devices

#: Compute shaders (the tile renderer) and storage buffers need OpenGL 4.3.
REQUIRED_VERSION = 430


class Backend(enum.Enum):
    EGL = "egl"
    OSMESA = "osmesa"


# OSMesa constants (GL/osmesa.h).
_OSMESA_FORMAT = 0x22
_OSMESA_RGBA = 0x1908
_OSMESA_DEPTH_BITS = 0x30
_OSMESA_PROFILE = 0x33
_OSMESA_CORE_PROFILE = 0x34
_OSMESA_CONTEXT_MAJOR_VERSION = 0x36
_OSMESA_CONTEXT_MINOR_VERSION = 0x37
_GL_UNSIGNED_BYTE = 0x1401


class _OSMesaLoader:
    """moderngl loader over ``OSMesaGetProcAddress``; owns the OSMesa context and its buffer."""

    def __init__(self) -> None:
        name = ctypes.util.find_library("OSMesa") or "libOSMesa.so.8"
        try:
            lib = ctypes.CDLL(name)
        except OSError as exc:
            raise ContextError(f"OSMesa library not found ({exc})") from None
        lib.OSMesaCreateContextAttribs.restype = ctypes.c_void_p
        lib.OSMesaCreateContextAttribs.argtypes = [ctypes.POINTER(ctypes.c_int), ctypes.c_void_p]
        lib.OSMesaMakeCurrent.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int,
                                          ctypes.c_int, ctypes.c_int]
        lib.OSMesaGetProcAddress.restype = ctypes.c_void_p
        lib.OSMesaGetProcAddress.argtypes = [ctypes.c_char_p]
        lib.OSMesaDestroyContext.argtypes = [ctypes.c_void_p]
        attribs = (ctypes.c_int * 11)(
            _OSMESA_FORMAT, _OSMESA_RGBA, _OSMESA_DEPTH_BITS, 0,
            _OSMESA_PROFILE, _OSMESA_CORE_PROFILE,
            _OSMESA_CONTEXT_MAJOR_VERSION, 4, _OSMESA_CONTEXT_MINOR_VERSION, 5, 0,
        )
        ctx = lib.OSMesaCreateContextAttribs(attribs, None)
        if not ctx:
            raise ContextError("OSMesaCreateContextAttribs failed for a 4.5 core context")
        # A 1x1 default framebuffer: splatgl always renders into its own framebuffers.
        self._buffer = (ctypes.c_ubyte * 4)()
        if not lib.OSMesaMakeCurrent(ctx, self._buffer, _GL_UNSIGNED_BYTE, 1, 1):
            lib.OSMesaDestroyContext(ctx)
            raise ContextError("OSMesaMakeCurrent failed")
        self._lib, self._ctx = lib, ctx

    def load_opengl_function(self, name: str) -> int:
        return self._lib.OSMesaGetProcAddress(name.encode()) or 0

    def __enter__(self):
        # moderngl calls this when the context is entered: make the OSMesa context current.
        if self._ctx:
            self._lib.OSMesaMakeCurrent(self._ctx, self._buffer, _GL_UNSIGNED_BYTE, 1, 1)
        return self

    def __exit__(self, *args):
        return None

    def release(self) -> None:
        if self._ctx:
            self._lib.OSMesaDestroyContext(self._ctx)
            self._ctx = None


def _egl_on(device: int | None) -> moderngl.Context:
    """An EGL context on EGL device ``device`` (None: glcontext's default, device 0)."""
    extra = {} if device is None else {"device_index": device}
    return moderngl.create_context(standalone=True, backend="egl", require=REQUIRED_VERSION, **extra)


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def _create_egl() -> moderngl.Context:
    """EGL on the device ``$SPLATGL_EGL_DEVICE`` names, else, where EGL lists several, on the
    first hardware device that gives a context with a hardware GL_RENDERER (software devices
    last).  ``ctx.extra`` records ``egl_device`` (the index, None for the default),
    ``egl_devices`` (how many EGL listed, None where it could not list them) and, where devices
    were tried, ``egl_skipped`` (why each one before the chosen one gave no context)."""
    devices = egl_devices.query_devices()
    count = None if devices is None else len(devices)
    asked = egl_devices.override_text(os.environ)
    if asked is not None:
        index = egl_devices.parse_override(asked, devices)
        try:
            ctx = _egl_on(index)
        except Exception as exc:
            raise ContextError(f"{egl_devices.DEVICE_ENV}={asked}: {_first_line(exc)}; "
                               f"{egl_devices.describe_devices(devices)}") from None
        ctx.extra = {"egl_device": index, "egl_devices": count}
        return ctx
    if devices is None or len(devices) <= 1:
        ctx = _egl_on(None)
        ctx.extra = {"egl_device": None, "egl_devices": count}
        return ctx
    fallback, failures = None, []
    for index in egl_devices.candidate_order(devices):
        try:
            ctx = _egl_on(index)
        except Exception as exc:  # a device EGL lists but cannot drive (no driver for it)
            failures.append(f"device {index}: {_first_line(exc)}")
            continue
        ctx.extra = {"egl_device": index, "egl_devices": count, "egl_skipped": list(failures)}
        if not egl_devices.is_software_renderer(ctx.info.get("GL_RENDERER", "")):
            if fallback is not None:
                fallback.release()
                make_current(ctx)
            return ctx
        if fallback is None:
            fallback = ctx  # software: used only if no device gives hardware rendering
        else:
            ctx.release()
            make_current(fallback)
    if fallback is not None:
        return fallback
    raise ContextError("no EGL device gave a context (" + "; ".join(failures) + ")")


def _create_osmesa() -> moderngl.Context:
    loader = _OSMesaLoader()
    moderngl.init_context(loader=loader)  # stores the context instead of returning it
    ctx = moderngl.get_context()
    ctx.extra = {"osmesa_loader": loader}  # keeps the OSMesa context alive with moderngl's
    if ctx.version_code < REQUIRED_VERSION:
        raise ContextError(f"OSMesa gave OpenGL {ctx.version_code}, need {REQUIRED_VERSION}")
    return ctx


_FACTORIES = {Backend.EGL: _create_egl, Backend.OSMESA: _create_osmesa}


def create_headless_context(backend: Backend | str | None = None) -> moderngl.Context:
    """A headless OpenGL 4.3+ core context; release it with ``ctx.release()``.

    Tries ``backend`` alone when given (or ``$SPLATGL_GL_BACKEND``), else EGL then OSMesa.
    Raises :class:`ContextError` listing every backend tried and why it failed.
    """
    chosen = backend or os.environ.get("SPLATGL_GL_BACKEND") or None
    device_asked = egl_devices.override_text(os.environ) is not None
    if device_asked and chosen is None:
        chosen = Backend.EGL  # a device was named: no quiet fall-back to OSMesa
    if chosen is not None:
        try:
            order = [Backend(chosen)]
        except ValueError:
            raise ContextError(f"unknown OpenGL backend {chosen!r} (choose egl or osmesa)") from None
        if device_asked and order != [Backend.EGL]:
            raise ContextError(f"{egl_devices.DEVICE_ENV} names an EGL device, but the OpenGL "
                               f"backend is {order[0].value}")
    else:
        order = [Backend.EGL, Backend.OSMESA]
    failures = []
    for b in order:
        try:
            return _FACTORIES[b]()
        except Exception as exc:  # each backend fails in its own way; all are reported below
            failures.append(f"{b.value}: {_first_line(exc)}")
    raise ContextError("could not create an OpenGL 4.3 context; tried " + "; ".join(failures))


#: What ``--timings`` and the machine line say where no OpenGL ran (the NumPy reference).
NO_GL_RENDERER = "none (NumPy reference, CPU only)"


def renderer_name(ctx: moderngl.Context) -> str:
    """The context's GL_RENDERER, with the EGL device where EGL listed several or one was
    named (``NVIDIA H100 80GB HBM3/PCIe/SSE2 (EGL device 0 of 2)``): what benchmarks and
    ``--timings`` print."""
    name = ctx.info.get("GL_RENDERER", "?")
    extra = getattr(ctx, "extra", None)
    extra = extra if isinstance(extra, dict) else {}
    if "osmesa_loader" in extra:
        return f"{name} (OSMesa)"
    index, count = extra.get("egl_device"), extra.get("egl_devices")
    if index is not None and (count or 0) != 1:
        return f"{name} (EGL device {index} of {count if count else '?'})"
    return name


@contextmanager
def glfw_errors():
    """Collect the GLFW errors of the block as text (``"X11: The DISPLAY environment variable
    is missing"``) in the list it yields, for the caller's one-line message, instead of
    pyGLFW's default of a raw ``(65550) b'X11: ...'`` warning per error."""
    import glfw

    messages: list[str] = []

    def collect(code: int, description) -> None:
        text = (description.decode("utf-8", "replace") if isinstance(description, bytes)
                else str(description))
        messages.append(" ".join(text.split()))

    previous = glfw.set_error_callback(collect)
    try:
        yield messages
    finally:
        glfw.set_error_callback(previous)   # None restores pyGLFW's default


#: Window context versions tried in order (DESIGN.md section 6: 4.5 works under Xvfb, 4.6 fails;
#: 4.3 is the least the renderers need; 3.3 only so the caller can say what is missing).
WINDOW_VERSIONS = ((4, 5), (4, 3), (3, 3))


def create_glfw_window(width: int, height: int, title: str, visible: bool = True):
    """Open a glfw window with a core-profile context, make it current.

    Returns ``(window, (major, minor), api)`` with ``api`` ``"egl"`` or ``"native"`` (GLX on
    X11).  Per version of :data:`WINDOW_VERSIONS`, EGL is tried first: a process that already
    made a headless EGL context (:func:`create_headless_context`) cannot make a GLX context
    current on the same display under Mesa (X error BadAccess, which ends the process), and
    EGL and EGL mix.  The caller decides what a version below :data:`REQUIRED_VERSION` can
    still do.  ``glfw.init()`` must have succeeded.  Raises :class:`ContextError` when no
    version gives a window.
    """
    import glfw

    failures = []
    for major, minor in WINDOW_VERSIONS:
        for api, hint in (("egl", glfw.EGL_CONTEXT_API), ("native", glfw.NATIVE_CONTEXT_API)):
            glfw.default_window_hints()
            glfw.window_hint(glfw.CONTEXT_CREATION_API, hint)
            glfw.window_hint(glfw.CONTEXT_VERSION_MAJOR, major)
            glfw.window_hint(glfw.CONTEXT_VERSION_MINOR, minor)
            glfw.window_hint(glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)
            glfw.window_hint(glfw.OPENGL_FORWARD_COMPAT, True)
            glfw.window_hint(glfw.VISIBLE, bool(visible))
            with glfw_errors() as errors:   # a refused try is no news: the next may work
                try:
                    window = glfw.create_window(width, height, title, None, None)
                except glfw.GLFWError:  # raised instead of returned when ERROR_REPORTING = 'raise'
                    window = None
            if window:
                glfw.make_context_current(window)
                return window, (major, minor), api
            failures.append(f"{major}.{minor} ({api}{': ' + errors[-1] if errors else ''})")
    raise ContextError("could not open a window with an OpenGL core context (tried "
                       + ", ".join(failures) + ")")


class _GlfwLoader:
    """moderngl loader over ``glfw.get_proc_address`` (EGL and GLX window contexts alike);
    entering it (what :func:`make_current` does) makes the window's context current."""

    def __init__(self, window) -> None:
        self.window = window

    def load_opengl_function(self, name: str) -> int:
        import glfw

        return glfw.get_proc_address(name) or 0

    def __enter__(self):
        import glfw

        glfw.make_context_current(self.window)
        return self

    def __exit__(self, *args):
        return None

    def release(self) -> None:
        return None


def create_glfw_context() -> moderngl.Context:
    """Wrap the current glfw window's context (EGL or GLX) in moderngl; the window owns it."""
    import glfw

    window = glfw.get_current_context()
    if not window:
        raise ContextError("no glfw window context is current")
    try:
        moderngl.init_context(loader=_GlfwLoader(window))
        return moderngl.get_context()
    except Exception as exc:
        raise ContextError(f"could not use the window's OpenGL context: {exc}") from None


def make_current(ctx: moderngl.Context) -> None:
    """Make ``ctx`` the current context of this thread, and leave it current.

    Creating a second context (a window, another renderer) makes that one current, and
    moderngl does not switch back by itself; every public entry point that issues GL calls on
    a context it holds calls this first.  (Unlike ``with ctx:``, nothing is restored later, so
    a released context is never made current again.)
    """
    ctx.__enter__()
