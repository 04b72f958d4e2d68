"""Transfer accounting (issue 40 item 3): the bytes a frame moves between host and device.

One :class:`Transfers` counter per GL context (:func:`transfers`).  The places that write or
read GL objects per frame count through it: :class:`~splatgl.gl.buffers.GrowableBuffer`'s
uploads and reads, the targets' image reads (:mod:`splatgl.gl.targets`), the quad path's
commands and geometry depth, the radix sort's plan, the uniforms of the programs a frame runs
(every active uniform's bytes: an upper bound of what the driver sends), and each wait for the
device (``finish`` or a read: a CPU-GPU synchronisation point).  A renderer takes
:meth:`Transfers.snapshot` before a frame and :meth:`TransferCounts.since` after it; what a
renderer uploads once per scene (its storage buffers) is made before the first snapshot and is
not a per-frame transfer.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import moderngl


@dataclass(frozen=True)
class TransferCounts:
    """Bytes uploaded and read back, and synchronisation points, since some moment."""

    uploaded: int = 0
    read_back: int = 0
    syncs: int = 0

    def since(self, earlier: "TransferCounts") -> "TransferCounts":
        return TransferCounts(self.uploaded - earlier.uploaded, self.read_back - earlier.read_back,
                              self.syncs - earlier.syncs)

    def text(self) -> str:
        """``per-frame uploads N bytes, read back N bytes, N syncs`` (``--timings``)."""
        return (f"per-frame uploads {self.uploaded:,} bytes, read back {self.read_back:,} bytes, "
                f"{self.syncs} syncs")

    def as_dict(self) -> dict[str, int]:
        """The bench JSON's fields."""
        return {"upload_bytes": self.uploaded, "readback_bytes": self.read_back,
                "syncs": self.syncs}


def uniform_bytes(prog) -> int:
    """Bytes of ``prog``'s active uniforms (4 per component)."""
    total = 0
    for name in prog:
        member = prog[name]
        if isinstance(member, moderngl.Uniform):
            total += 4 * member.dimension * max(1, member.array_length)
    return total


class Transfers:
    """The running totals of one context (see the module doc)."""

    def __init__(self) -> None:
        self.uploaded = 0
        self.read_back = 0
        self.syncs = 0

    def upload(self, nbytes: int) -> None:
        self.uploaded += int(nbytes)

    def write(self, obj, data: bytes) -> None:
        """``obj.write(data)`` (a buffer or texture), counted."""
        obj.write(data)
        self.uploaded += len(data)

    def uniforms(self, prog) -> None:
        """Count the uniforms of ``prog`` (set for one run or draw)."""
        self.uploaded += uniform_bytes(prog)

    def read(self, nbytes: int) -> None:
        """A read of ``nbytes`` from the device (a synchronisation point)."""
        self.read_back += int(nbytes)
        self.syncs += 1

    def sync(self) -> None:
        """A wait for the device (``ctx.finish()``)."""
        self.syncs += 1

    def snapshot(self) -> TransferCounts:
        return TransferCounts(self.uploaded, self.read_back, self.syncs)


_COUNTERS: "weakref.WeakKeyDictionary[object, Transfers]" = weakref.WeakKeyDictionary()


def transfers(ctx) -> Transfers:
    """The counter of ``ctx`` (made on first use)."""
    counter = _COUNTERS.get(ctx)
    if counter is None:
        counter = _COUNTERS[ctx] = Transfers()
    return counter
