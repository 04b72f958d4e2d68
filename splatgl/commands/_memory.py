"""``--memory SIZE``: the one option (and default) bounding a command's peak memory, shared by
``lod``, ``edit``, ``convert`` and ``info`` (parsing and the default live in
:mod:`splatgl.lod.budget`: a fraction of this machine's RAM)."""

from __future__ import annotations

import argparse

from ..lod.budget import budget_from


def add_memory_argument(p: argparse.ArgumentParser, what: str) -> None:
    """Add ``--memory SIZE``; ``what``: how the command keeps within it (for the help)."""
    p.add_argument("--memory", default=None, metavar="SIZE",
                   help="peak memory, e.g. 200M or 4G (default: half this machine's RAM); "
                        + what)


def memory_budget(args: argparse.Namespace) -> int:
    """Bytes of ``--memory`` (its default when not given)."""
    return budget_from(getattr(args, "memory", None))[0]
