"""The options of the reference's emulation knobs and of the per-pixel order, shared by the
commands that render (:func:`splatgl.commands._common.add_settings_arguments`)."""

from __future__ import annotations

import argparse

from ..scene.emulation import parse_emulation
from ..scene.settings import DEFAULT_ORDER_WINDOW, MAX_ORDER_WINDOW, Order

EMULATE_HELP = ("follow another viewer's approximation in the NumPy reference (repeatable): "
                "sort=exact|bucket16, extent=tiles|fixed|fixed-quad|square|opacity, "
                "min_alpha=A, low_pass=PX2, compensation=on|off, sh=0-3, half=on|off, "
                "alpha_max=A, depth=auto|z|distance (docs/fidelity.md); the quad, tile and "
                "cpu renderers refuse it")


def add_fidelity_arguments(g: argparse._ArgumentGroup) -> None:
    """--order, --order-window and --emulate."""
    g.add_argument("--order", choices=[o.value for o in Order], default=Order.GLOBAL.value,
                   help="blend order: 'global' = every pixel in the order of the splats' "
                        "centres (3DGS; default), 'per-pixel' = each pixel sorts its splats by "
                        "the depth of their peak along its ray, which removes popping (tile "
                        "renderer: a window of --order-window splats; reference: exact; "
                        "perspective and orthographic cameras; docs/fidelity.md)")
    g.add_argument("--order-window", type=_window, default=DEFAULT_ORDER_WINDOW, metavar="N",
                   help=f"with --order per-pixel, splats the tile renderer holds back per pixel "
                        f"(1-{MAX_ORDER_WINDOW}, default {DEFAULT_ORDER_WINDOW}; another value is "
                        f"refused without --order per-pixel and by the other renderers, the "
                        f"reference sorting exactly)")
    g.add_argument("--emulate", action="append", default=None, metavar="KNOB=VALUE",
                   help=EMULATE_HELP)


def _window(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if not 1 <= value <= MAX_ORDER_WINDOW:
        raise argparse.ArgumentTypeError(f"must be 1..{MAX_ORDER_WINDOW}, got {value}")
    return value


def fidelity_fields(args: argparse.Namespace) -> dict:
    """The RenderSettings fields these options give (defaults where a command lacks them)."""
    return {"emulation": parse_emulation(getattr(args, "emulate", None)),
            "order": Order(getattr(args, "order", None) or Order.GLOBAL.value),
            "order_window": getattr(args, "order_window", None) or DEFAULT_ORDER_WINDOW}
