"""A GPU buffer that grows to the size asked for and is reused across frames (never shrinks)."""

from __future__ import annotations

import moderngl
import numpy as np

from .limits import DERIVED_ADVICE, buffer_limit, check_splat_buffer
from .transfers import transfers


class GrowableBuffer:
    """One moderngl buffer, re-created larger when a frame needs more bytes than it holds.

    ``slack``: extra room on growth (a share of the size asked for), so that slowly growing
    sizes do not re-create the buffer every frame.  ``minimum``: the smallest size made (a
    zero-byte buffer cannot be bound).  ``binding``: the storage-buffer slot :meth:`bind` uses.
    After :meth:`ensure`, :attr:`grew` tells whether the buffer object changed (vertex arrays
    that read it must then be rebuilt).  Each growth goes through the driver's buffer limit
    (:func:`splatgl.gl.limits.check_splat_buffer`): a size past it is refused in one line before
    anything is allocated (``what`` names the buffer, ``stride`` bytes per ``unit`` give the
    count), and the slack never takes a buffer past it.
    """

    def __init__(self, ctx: moderngl.Context, binding: int | None = None, slack: float = 0.0,
                 minimum: int = 16, what: str = "a per-view buffer", stride: int = 0,
                 unit: str = "splats"):
        self.ctx, self.binding, self.slack, self.minimum = ctx, binding, slack, minimum
        self.what, self.stride, self.unit = what, stride, unit
        self.buf: moderngl.Buffer | None = None
        self.grew = False

    def ensure(self, nbytes: int) -> moderngl.Buffer:
        """The buffer, at least ``nbytes`` (and :attr:`minimum`) bytes large."""
        nbytes = max(int(nbytes), self.minimum)
        self.grew = self.buf is None or self.buf.size < nbytes
        if self.grew:
            check_splat_buffer(self.ctx, nbytes // self.stride if self.stride else None, nbytes,
                               self.what, self.unit, DERIVED_ADVICE)
            size = min(nbytes + int(nbytes * self.slack), max(nbytes, buffer_limit(self.ctx)[0]))
            if self.buf is not None:
                self.buf.release()
            self.buf = self.ctx.buffer(reserve=size)
        return self.buf

    def upload(self, data: bytes) -> moderngl.Buffer:
        """Write ``data`` at the start (growing first if needed)."""
        buf = self.ensure(len(data))
        if data:
            transfers(self.ctx).write(buf, data)
        return buf

    def bind(self, binding: int | None = None) -> None:
        """Bind to its storage slot (or ``binding``)."""
        self.ensure(self.minimum).bind_to_storage_buffer(self.binding if binding is None else binding)

    def read(self, nbytes: int, dtype) -> np.ndarray:
        if nbytes:
            transfers(self.ctx).read(nbytes)
        return np.frombuffer(self.buf.read(size=nbytes), dtype) if nbytes else np.zeros(0, dtype)

    def release(self) -> None:
        if self.buf is not None:
            self.buf.release()
        self.buf = None
