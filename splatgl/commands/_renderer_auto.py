"""The commands' side of ``auto`` (issue 40 item 4): ``--renderer auto`` resolved for one request
(:mod:`splatgl.renderers.auto`), and the lines ``--timings`` prints for every ``auto`` option
("renderer auto -> cpu (...)", "sort auto -> exact (llvmpipe: software)")."""

from __future__ import annotations

import argparse

from ..gl.device_class import AUTO, choice_text, classify, expected, resolve_early_stop
from ..scene.settings import RendererKind, RenderSettings
from ..renderers import auto as renderer_auto

__all__ = ["AUTO", "auto_lines", "choose_renderer"]


def choose_renderer(args: argparse.Namespace, scene, settings: RenderSettings, camera, layers,
                    under, background: bool = False) -> RendererKind:
    """``--renderer auto`` for this request: sets ``args.renderer`` to the choice (and
    ``args.renderer_choice``, for ``--timings``).  Where only the CPU renderer's kernels were
    missing: ``background`` (the viewer) compiles them on a thread now, a one-shot command in a
    process of its own (:mod:`splatgl.renderers.kernel_build`); either way it is said once on
    stderr."""
    choice = renderer_auto.choose(scene=scene, settings=settings,
                                  model=camera.model if camera is not None else None,
                                  layers=frozenset(layers) if layers is not None else None,
                                  under=under is not None)
    args.renderer = choice.kind.value
    args.renderer_choice = choice
    if choice.kernels_missing:
        if background:
            renderer_auto.compile_in_background()
        renderer_auto.compiling_notice(choice, background, detach=not background)
    return choice.kind


def auto_lines(args: argparse.Namespace, settings: RenderSettings, gl_name: str | None = None) -> list[str]:
    """What each ``auto`` option became: the renderer, the sort and (quad path) early
    termination, with the device that decided (``gl_name``: the GL renderer that drew, where
    one did)."""
    choice = getattr(args, "renderer_choice", None)
    lines = [choice.text()] if choice is not None else []
    device = classify(gl_name) if gl_name and not gl_name.startswith("none") else expected()
    if getattr(args, "sort", None) == AUTO and args.renderer in ("quad", "tile"):
        lines.append(choice_text("sort", settings.sort_key.value, device))
    if getattr(args, "early_stop", None) is None and args.renderer == "quad":
        stop = resolve_early_stop(settings.early_stop, device).value
        lines.append(choice_text("early-stop", "by coverage" if stop == AUTO else stop, device))
    return lines
