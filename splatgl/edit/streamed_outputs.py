"""Streamed outputs other than binary PLY (issue 41 item 5): ``convert``/``edit --memory`` of a
binary PLY larger than the budget write ``.splat`` and ``.compressed.ply`` a block at a time,
byte for byte what the in-memory writers write.

- ``.splat`` (:mod:`splatgl.formats.splat`) is row-wise: each block's rows are encoded and
  appended (a scale beyond float32 is named by its row in the whole result, as in memory).
- ``.compressed.ply`` (:mod:`splatgl.formats.compressed_ply_write`) stores the splats in the
  Morton order of their bounding box, in chunks of 256 rows with per-chunk bounds, the chunk
  element before the vertices: a pass finds the box, the blocks are sorted by that order on
  disk (:mod:`.streamed_sort`), and pieces of whole chunks are encoded in order into three
  scratch files, joined behind the header at the end.

Either file goes through the atomic writer (:mod:`splatgl.writing.atomic`): nothing
half-written on an error, Ctrl-C or SIGTERM.  Other formats (SPZ, SOG, glTF) are
compressed or ordered as a whole: over the budget they are refused in one line
(:func:`refusal`).  :class:`RoundTrip` measures ``convert``'s round trip piece by piece, each
piece decoded from the bytes written for it.
"""

from __future__ import annotations

import re
import shutil

import numpy as np

from ..errors import SceneFormatError, SplatglError
from ..formats import compressed_ply, splat
from ..formats import compressed_ply_write as cpw
from ..formats.convert import conversion_error, error_bounds
from ..formats.ply_write import _header, _ordered
from ..formats.written import written_problem
from ..lod.budget import format_size
from ..scene.splats import Scene, SplatKind, activate
from ..writing.atomic import atomic_target, size_problem
from .streamed_sort import scratch

#: Output formats written a block at a time.
STREAMED_FORMATS = ("ply", "splat", "compressed_ply")
#: A compressed PLY's sorted runs and pieces hold this share of a block's rows (the encoder's
#: and the round trip's float64 temporaries of every SH value: about 4 KB a row at SH3,
#: against the block's 2.2 KB; measured at 1M SH3 under --memory 300M: 388 MB peak with
#: whole blocks, 222 MB with a third).
PIECE_SHARE = 3
#: The per-attribute errors :func:`conversion_error` gives as ``{"max", "mean"}``.
MEASURED = ("position", "scale", "opacity", "rotation", "color", "sh_rest")


#: A format written whole peaks at this many times the decoded scene's bytes (the scene, the
#: encoder's arrays, the file's bytes and convert's read back; measured on a 1.5M-splat SH0
#: PLY: .spz 4.3x, .sog 4.2x, .glb 5.2x, where the refusal counted 2x and let 2.1-2.6x more
#: through).
WHOLE_WRITE_COPIES = {"gltf": 5.5}
WHOLE_WRITE_DEFAULT = 4.5


def whole_write_bytes(name: str, scene_bytes: int) -> int:
    """Bytes writing a scene of ``scene_bytes`` (decoded) in format ``name`` takes, whole."""
    return int(WHOLE_WRITE_COPIES.get(name, WHOLE_WRITE_DEFAULT) * scene_bytes)


def refusal(output, name: str, need: int, memory: int) -> SplatglError:
    """The one line refusing an output format written whole, over the budget."""
    return SplatglError(f"{output}: the {name} format is written from the whole scene in memory "
                        f"(about {format_size(need)}, over --memory {format_size(memory)}); "
                        "write .ply, .splat or .compressed.ply, which stream, or give a larger "
                        "--memory")


def check_kind(output, name: str, kind: SplatKind) -> None:
    """The writers' refusal of 2DGS surfels, before anything is read."""
    if kind is not SplatKind.GAUSSIAN_3D and name == "splat":
        raise SceneFormatError(output, ".splat stores 3D Gaussians only; cannot write a 2DGS "
                                       "surfel scene (write .ply instead)", "scale")
    if kind is not SplatKind.GAUSSIAN_3D and name == "compressed_ply":
        cpw._check(output, Scene(np.zeros((0, 3), np.float32), np.zeros((0, 4), np.float32),
                                 np.zeros((0, 2), np.float32), np.zeros(0, np.float32),
                                 np.zeros((0, 1, 3), np.float32), kind))


class RoundTrip:
    """:func:`conversion_error` (and the writer's bounds) over pieces: :meth:`add` each piece
    and what was read back of it, :meth:`result` the whole file's."""

    def __init__(self, writer=None):
        self.writer = writer
        self.total, self.sums, self.out, self.bounds = 0, {}, None, None

    def add(self, a: Scene, b: Scene) -> None:
        e = conversion_error(a, b)
        if self.out is None:
            self.out = dict(e)
        else:
            out = self.out
            out["bit_exact"] = out["bit_exact"] and e["bit_exact"]
            out["dropped"] += [n for n in e["dropped"] if n not in out["dropped"]]
            out["color_outside_01"] += e["color_outside_01"]
            for name in MEASURED:
                if e[name] is not None:
                    out[name] = {"max": max(out[name]["max"], e[name]["max"]),
                                 "mean": out[name]["mean"]}
        for name in MEASURED:
            if e[name] is not None:
                self.sums[name] = self.sums.get(name, 0.0) + e[name]["mean"] * a.count
        self.total += a.count
        if self.writer is not None:
            bounds = error_bounds(self.writer, a)
            if bounds is not None:  # the largest of the pieces' bounds
                self.bounds = bounds if self.bounds is None else {
                    k: v if self.bounds[k] is None else max(v, self.bounds[k])
                    for k, v in bounds.items()}

    def result(self) -> dict:
        out = self.out
        out["count"] = self.total
        for name in MEASURED:
            if out[name] is not None:
                out[name]["mean"] = self.sums[name] / self.total
        out["bounds"] = self.bounds
        out["within_bounds"] = None if self.bounds is None else {
            name: bool(out[name]["max"] <= self.bounds[name]) for name in MEASURED
            if self.bounds.get(name) is not None and out.get(name) is not None}
        return out


def _row_named(exc: SceneFormatError, first: int) -> SceneFormatError:
    """``exc`` naming its row in the whole result (``first``: the block's first row)."""
    exc.args = (re.sub(r"row (\d+):", lambda m: f"row {first + int(m.group(1))}:", str(exc),
                       count=1),)
    return exc


def write_splat(output, count: int, blocks, trip: RoundTrip | None = None) -> int:
    """Write the ``count`` rows ``blocks`` yields (Scenes of SH degree 0) as ``.splat``."""
    expected = count * splat.ROW_BYTES
    with atomic_target(output, lambda tmp: size_problem(tmp, expected)) as tmp:
        with open(tmp, "wb") as fh:
            first = 0
            for block in blocks:
                try:
                    rows = splat.encode(block, output)
                except SceneFormatError as exc:
                    raise _row_named(exc, first) from None
                rows.tofile(fh)
                if trip is not None:
                    trip.add(block, splat.decode(output, rows))
                first += block.count
    return expected


def whole_chunks(scenes):
    """The Scenes ``scenes`` yields regrouped into pieces of whole chunks (CHUNK_SIZE rows;
    the last piece the rest)."""
    held, n = [], 0
    for s in scenes:
        held.append(s)
        n += s.count
        if n >= compressed_ply.CHUNK_SIZE:
            joined = concat(held)
            cut = n // compressed_ply.CHUNK_SIZE * compressed_ply.CHUNK_SIZE
            yield joined.subset(slice(0, cut))
            n -= cut
            held = [joined.subset(slice(cut, cut + n))] if n else []
    if n:
        yield concat(held)


def concat(scenes: list[Scene]) -> Scene:
    """The rows of ``scenes`` in order, one Scene (no extras)."""
    if len(scenes) == 1 and scenes[0].extras is None:
        return scenes[0]
    return Scene(*(np.concatenate([getattr(s, f) for s in scenes]) for f in
                   ("means", "quats", "log_scales", "opacity_logits", "sh")), scenes[0].kind)


def write_compressed(output, count: int, pieces, trip: RoundTrip | None = None) -> int:
    """Write the ``count`` rows ``pieces`` yields (Scenes in Morton order, whole chunks but the
    last: :func:`whole_chunks`) as compressed PLY; its bytes."""
    names = ("chunk", "vertex", "sh")
    chunks = -(-count // compressed_ply.CHUNK_SIZE)
    with scratch(output) as folder:
        parts = {name: open(folder / name, "w+b") for name in names}
        try:
            dtypes = {}
            for piece in pieces:
                elements = cpw.encode(piece, np.arange(piece.count))
                for name, arr in elements:
                    dtypes[name] = arr.dtype
                    _ordered(arr, "<").tofile(parts[name])
                if trip is not None:
                    trip.add(piece, _decoded(output, elements))
            head = _header([(name, chunks if name == "chunk" else count, dtypes[name])
                            for name in names if name in dtypes], "little", False,
                           [cpw.COMMENT])
            with atomic_target(output, written_problem) as tmp:
                with open(tmp, "wb") as out:
                    out.write(head)
                    for name in names:
                        parts[name].seek(0)
                        shutil.copyfileobj(parts[name], out, 1 << 20)
        finally:
            for fh in parts.values():
                fh.close()
        return output.stat().st_size


def _decoded(output, elements) -> Scene:
    """The Scene a reader gets from the bytes written for one piece."""
    data = _header([(n, len(a), a.dtype) for n, a in elements], "little", False, [cpw.COMMENT])
    data += b"".join(_ordered(a, "<").tobytes() for _, a in elements)
    means, quats, log_scales, logits, sh = compressed_ply.decode(output, data)
    return activate(output, means, quats, log_scales, logits, sh, SplatKind.GAUSSIAN_3D)
