"""``--target-fps F``: the viewer's frame-time budget, one option for ``view``, ``render --path
--preview`` and ``bench --interactive`` (its check, :func:`splatgl.interactive.budget.check_fps`,
and its default, :func:`splatgl.interactive.session.default_fps`, live in the library)."""

from __future__ import annotations

import argparse

from ..interactive.session import GPU_FPS, SOFTWARE_FPS


def add_target_fps_argument(p: argparse.ArgumentParser | argparse._ArgumentGroup, what: str,
                            zero: str = "") -> None:
    """Add ``--target-fps``; ``what``: what the budget paces in this command (for the help),
    ``zero``: what 0 means here, where the command takes it."""
    p.add_argument("--target-fps", type=float, default=None, metavar="F",
                   help=f"{what} (default: {SOFTWARE_FPS:g} on software OpenGL such as llvmpipe, "
                        f"{GPU_FPS:g} on a GPU{'; 0: ' + zero if zero else ''})")
