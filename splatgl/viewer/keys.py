"""The viewer's keyboard: what each key does (the list shown with H is :data:`.overlay.KEYS`).

Fly and roll keys are held: :class:`~.navigation.Navigation` moves by them every frame until
they are released.  The rest act once per press (the field of view also on auto-repeat), on the
:class:`~.app.Viewer`'s camera, settings, renderer kind, view mode and panel.
"""

from __future__ import annotations

import glfw

from ..scene.settings import Precision, RendererKind
from ..renderers import registry
from . import controls, recorder
from .modes import ViewMode
from .overlay import key_help

#: Keys that act on auto-repeat too (field of view); the rest act once per press.
REPEATING = (glfw.KEY_LEFT_BRACKET, glfw.KEY_RIGHT_BRACKET, glfw.KEY_MINUS, glfw.KEY_EQUAL,
             glfw.KEY_KP_ADD, glfw.KEY_KP_SUBTRACT)
#: The backgrounds B cycles through (from one that is none of them: the first).
BACKGROUNDS = ((0.0, 0.0, 0.0), (1.0, 1.0, 1.0), (0.5, 0.5, 0.5))
#: The blend precisions P cycles through.
PRECISIONS = (Precision.RGBA32F, Precision.RGBA16F, Precision.RGBA8)


def on_key(v, key: int, action: int, mods: int) -> None:
    """Act on a glfw key event (``key``, ``action`` and ``mods`` as glfw reports them) in the
    viewer ``v``; anything but a release or a held key asks for a new present."""
    v.nav.shift = bool(mods & glfw.MOD_SHIFT)
    ctrl = bool(mods & glfw.MOD_CONTROL)
    if action == glfw.RELEASE:
        v.nav.release(key)
        return
    if not ctrl and v.nav.hold(key):
        return  # acts in step() for as long as it is held
    if action != glfw.PRESS and key not in REPEATING:
        return  # the rest act once per press, not on auto-repeat
    if key == glfw.KEY_ESCAPE:
        glfw.set_window_should_close(v.window, True)
    elif key == glfw.KEY_R:
        v.state = controls.reset(v.state, v.home)
    elif key in (glfw.KEY_LEFT_BRACKET, glfw.KEY_MINUS, glfw.KEY_KP_SUBTRACT):
        v.state = controls.change_fov(v.state, -2.0)
    elif key in (glfw.KEY_RIGHT_BRACKET, glfw.KEY_EQUAL, glfw.KEY_KP_ADD):
        v.state = controls.change_fov(v.state, 2.0)
    elif key in (glfw.KEY_N, glfw.KEY_PAGE_DOWN, glfw.KEY_PAGE_UP):
        back = key == glfw.KEY_PAGE_UP or (key == glfw.KEY_N and v.nav.shift)
        v.step_camera(-1 if back else 1)
    elif key == glfw.KEY_T:
        next_renderer(v)
    elif glfw.KEY_0 <= key <= glfw.KEY_3:
        v.set_settings(sh_degree=key - glfw.KEY_0)
    elif key == glfw.KEY_P:
        i = PRECISIONS.index(v.settings.precision)
        v.set_settings(precision=PRECISIONS[(i + 1) % len(PRECISIONS)])
    elif key == glfw.KEY_D and ctrl:
        v.view = ViewMode.COLOR if v.view is ViewMode.DEPTH else ViewMode.DEPTH
    elif key == glfw.KEY_TAB:
        modes = list(ViewMode)
        view = modes[(modes.index(v.view) + 1) % len(modes)]
        if view is ViewMode.DIFFERENCE and not tile_allowed(v, "Tab skipped the difference view"):
            view = modes[(modes.index(view) + 1) % len(modes)]   # skip it: one press, one view
        v.view = view
    elif key == glfw.KEY_C:
        if v.view is ViewMode.DIFFERENCE:
            v.view = ViewMode.COLOR
        elif tile_allowed(v, "C refused"):
            v.view = ViewMode.DIFFERENCE
    elif key == glfw.KEY_F12 or (key == glfw.KEY_S and ctrl):
        v.screenshot()
    elif key == glfw.KEY_K:
        v.message = recorder.toggle(v)
    elif key == glfw.KEY_B:
        i = next((i for i, bg in enumerate(BACKGROUNDS) if bg == v.settings.background), -1)
        v.set_settings(background=BACKGROUNDS[(i + 1) % len(BACKGROUNDS)])
        v.message = "background " + ",".join(f"{c:g}" for c in v.settings.background)
    elif key == glfw.KEY_U:
        v.message = f"up {v.nav.cycle_up()} (U cycles +y / -y / +z / -z)"
    elif key == glfw.KEY_I:
        v.overlay.visible = not v.overlay.visible
    elif key == glfw.KEY_H:
        v.overlay.show_keys = not v.overlay.show_keys
        if v.overlay.show_keys:
            print("keys:\n" + key_help(), flush=True)
    v.need_present = True


#: The renderers T steps through, in order: every one that draws at a window's pace.
_CYCLE = tuple(RendererKind(name) for name in registry.names(interactive=True))


def refusal(v, kind: RendererKind) -> str | None:
    """Why ``kind`` cannot draw viewer ``v``'s current view (the first clause of its error),
    or None (:func:`splatgl.renderers.registry.refusal`)."""
    why = registry.refusal(kind, scene=v.scene, settings=v.settings, model=v.camera().model)
    return None if why is None else why.split(";")[0].split(" (use ")[0]


def tile_allowed(v, what: str) -> bool:
    """Whether the tile renderer can draw the current view (the difference view's other
    side); if not, the status line says why after ``what`` ("C refused") and the view stays."""
    why = refusal(v, RendererKind.TILE)
    if why is not None:
        v.message = f"{what}: {why}"
    return why is None


def next_renderer(v) -> None:
    """T: the next of quad, tile and cpu that can draw this view.  One that cannot is
    skipped and the status line says why; if none can, nothing changes."""
    start = _CYCLE.index(v.kind) if v.kind in _CYCLE else 0
    skipped = []
    for step in range(1, len(_CYCLE)):
        kind = _CYCLE[(start + step) % len(_CYCLE)]
        why = refusal(v, kind)
        if why is None:
            v.kind = kind
            if skipped:
                v.message = f"T skipped {'; '.join(skipped)}"
            return
        skipped.append(f"{kind.value}: {why}")
    v.message = f"T refused: {'; '.join(skipped)}"
