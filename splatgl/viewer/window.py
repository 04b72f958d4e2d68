"""The viewer's glfw window: opening it with an OpenGL 4.3+ context, wiring its callbacks to
the viewer's ``on_*`` handlers, swapping, closing it."""

from __future__ import annotations

import time

import glfw
import moderngl

from ..errors import SplatglError
from ..gl.context import REQUIRED_VERSION, create_glfw_context, create_glfw_window, glfw_errors


def open_window(width: int, height: int, title: str, visible: bool = True,
                vsync: bool = True) -> tuple[object, moderngl.Context, str]:
    """A ``width`` x ``height`` window and its moderngl context (current); returns
    ``(window, ctx, context_api)``.  Refused (:class:`SplatglError`, glfw shut down again)
    without a display or without an OpenGL 4.3 window context."""
    with glfw_errors() as errors:   # GLFW's reason goes into the one line, not a raw b'X11: ...'
        ready = glfw.init()
    if not ready:
        raise SplatglError("cannot open a window: glfw failed to initialise ("
                           + (f"{errors[-1]}; " if errors else "no display? ")
                           + "set DISPLAY, e.g. run under Xvfb)")
    window = None
    try:
        window, version, context_api = create_glfw_window(width, height, title, visible)
        if version[0] * 100 + version[1] * 10 < REQUIRED_VERSION:
            raise SplatglError(
                f"only an OpenGL {version[0]}.{version[1]} window context is available; the "
                "viewer needs 4.3 (storage buffers for the quad path, compute shaders for "
                "the tile path). Use `splatgl render` (headless EGL) instead")
        ctx = create_glfw_context()
    except Exception:
        close_window(window)
        raise
    glfw.swap_interval(1 if vsync else 0)
    return window, ctx, context_api


def connect(window, handler) -> None:
    """Route ``window``'s glfw callbacks to ``handler``'s ``on_key``, ``on_mouse_button``,
    ``on_cursor``, ``on_scroll``, ``on_resize``, ``on_refresh`` and ``on_focus``."""
    glfw.set_key_callback(window, lambda _w, key, sc, action, mods: handler.on_key(key, action, mods))
    glfw.set_mouse_button_callback(window, lambda _w, b, action, mods: handler.on_mouse_button(b, action, mods))
    glfw.set_cursor_pos_callback(window, lambda _w, x, y: handler.on_cursor(x, y))
    glfw.set_scroll_callback(window, lambda _w, dx, dy: handler.on_scroll(dx, dy))
    glfw.set_framebuffer_size_callback(window, lambda _w, fw, fh: handler.on_resize(fw, fh))
    glfw.set_window_refresh_callback(window, lambda _w: handler.on_refresh())
    glfw.set_window_focus_callback(window, lambda _w, focused: handler.on_focus(bool(focused)))


def swap(window, vsync: bool) -> float:
    """Swap ``window``'s buffers; returns the seconds the swap waited without working.

    With vsync a swap's wall time is partly waiting for the display's refresh: idle, not the
    window's cost to a frame budget (a 60 fps budget would shrink the draw to what leaves the
    wait).  This thread's CPU time is the work it did (a software swap copies the image here);
    the process's would count the background level-of-detail build.  Without vsync: 0."""
    wall, cpu = time.perf_counter(), time.thread_time()
    glfw.swap_buffers(window)
    if not vsync:
        return 0.0
    return max(0.0, (time.perf_counter() - wall) - (time.thread_time() - cpu))


def close_window(window) -> None:
    """Destroy ``window`` (if any) and shut glfw down."""
    if window:
        glfw.destroy_window(window)
    glfw.terminate()
