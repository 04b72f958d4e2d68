"""``--spz-axes rub|rdf`` for the commands that read or write SPZ (see
:mod:`splatgl.formats.spz_axes`)."""

from __future__ import annotations

import argparse

from ..errors import SplatglError
from ..formats.spz_axes import CHOICES

READ_HELP = ("axes of an .spz scene that records none: rub (the SPZ specification; the default "
             "for versions 3-4) or rdf (PLY axes as is, e.g. from splat-transform 3.x)")


def add_spz_axes_argument(p: argparse.ArgumentParser, help_text: str = READ_HELP) -> None:
    p.add_argument("--spz-axes", choices=CHOICES, default=None, type=str.lower, help=help_text)


def check_not_sharded(args: argparse.Namespace, sharded: bool) -> None:
    """Workers load the scene file themselves, without ``--spz-axes``: refuse the pair."""
    if sharded and getattr(args, "spz_axes", None):
        raise SplatglError("--spz-axes does not reach --workers / --executor ray: record the axes "
                           "in the file first (splatgl convert IN.spz OUT.spz --spz-axes "
                           f"{args.spz_axes}) and use OUT.spz")
