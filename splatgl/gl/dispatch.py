"""Compute dispatches of any number of work groups.

A dispatch of more than ``GL_MAX_COMPUTE_WORK_GROUP_COUNT`` groups along x (65535 on llvmpipe
and on most GPUs' y and z) does nothing at all, with no GL error: the frame comes out black.
Every per-item compute pass therefore dispatches through this module:

- :func:`run` (a direct dispatch of ``groups`` groups) splits it into dispatches of at most
  :func:`group_limit` groups, setting the program's ``u_group_offset`` (shaders/lib/
  dispatch.glsl: ``linear_group()``, ``linear_invocation()``) to each one's first group;
- :func:`run_indirect` (sizes written on the device) takes the most groups the device can have
  written: a plan shader that splits its sizes itself (``split_groups()`` in
  lib/dispatch.glsl, its ``u_group_limit`` set by :func:`set_limit`) writes x and y, and the
  shader reads its group as ``linear_group()``, bounds-checking the tail.

A pass whose shader does not split (no ``u_group_offset``) is refused in one line
(:class:`~splatgl.errors.SplatglError`) before a dispatch that would exceed the limit, so no
dispatch silently draws nothing.
"""

from __future__ import annotations

import moderngl

from ..errors import SplatglError

#: The limit assumed where the context does not report one (the GL 4.3 minimum).
DEFAULT_LIMIT = 65535
#: Tests set this to a few groups so that small scenes exercise the split (None: the context's).
LIMIT_OVERRIDE: int | None = None

_limits: dict[int, int] = {}


def group_limit(ctx: moderngl.Context) -> int:
    """The most work groups one dispatch may have along x and along y on ``ctx``."""
    if LIMIT_OVERRIDE is not None:
        return max(1, int(LIMIT_OVERRIDE))
    key = id(ctx)
    if key not in _limits:
        try:
            counts = ctx.info["GL_MAX_COMPUTE_WORK_GROUP_COUNT"]
            _limits[key] = max(1, min(int(counts[0]), int(counts[1]), DEFAULT_LIMIT))
        except (KeyError, TypeError, ValueError, IndexError):
            _limits[key] = DEFAULT_LIMIT
    return _limits[key]


def portable_limit() -> int:
    """The limit every OpenGL 4.3 context has (65535), for dispatches sized without a context
    (the tile renderer's 2-D splat dispatches); :data:`LIMIT_OVERRIDE` where set."""
    return DEFAULT_LIMIT if LIMIT_OVERRIDE is None else max(1, int(LIMIT_OVERRIDE))


def grid(groups: int, limit: int) -> tuple[int, int]:
    """(x, y) groups covering ``groups`` with neither above ``limit``: y = ceil(groups / limit),
    x = ceil(groups / y) (the tail, x * y - groups, is under y groups)."""
    groups = max(1, int(groups))
    y = -(-groups // limit)
    return -(-groups // y), y


def too_many(groups: int, limit: int, what: str) -> SplatglError:
    """The one-line refusal of a dispatch of ``groups`` groups that is not split."""
    return SplatglError(f"{what} need {groups} work groups, over this driver's {limit} in one "
                        "compute dispatch; draw fewer splats or use --renderer cpu")


def run(prog: moderngl.ComputeShader, groups: int, what: str) -> None:
    """Dispatch ``groups`` work groups of ``prog`` (1-D), split into dispatches of at most
    :func:`group_limit` groups (``u_group_offset``) where there are more; ``what`` names the
    items in the refusal (e.g. "8500000 splats") where the shader cannot be split."""
    groups = int(groups)
    if groups <= 0:
        return
    limit = group_limit(prog.ctx)
    split = "u_group_offset" in prog
    if groups > limit and not split:
        raise too_many(groups, limit, what)
    for first in range(0, groups, limit):
        if split:
            prog["u_group_offset"].value = first
        prog.run(group_x=min(limit, groups - first))
    if split and groups > limit:
        prog["u_group_offset"].value = 0


def run_indirect(prog: moderngl.ComputeShader, buffer: moderngl.Buffer, offset: int,
                 most: int, what: str, split: bool = False) -> None:
    """``prog.run_indirect(buffer, offset)`` whose device-written size is at most ``most``
    groups (along x, or in all where the plan wrote a split ``split_groups()`` size: ``split``).
    Refused in one line where an unsplit size could exceed the limit."""
    limit = group_limit(prog.ctx)
    if not split and most > limit:
        raise too_many(int(most), limit, what)
    if "u_group_offset" in prog:
        prog["u_group_offset"].value = 0
    prog.run_indirect(buffer, offset)


def set_limit(prog: moderngl.ComputeShader) -> None:
    """Set a plan shader's ``u_group_limit`` (the split its ``split_groups()`` writes)."""
    if "u_group_limit" in prog:
        prog["u_group_limit"].value = group_limit(prog.ctx)
