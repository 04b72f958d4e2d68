"""INRIA-style 3DGS / 2DGS PLY files (binary little/big endian and ASCII): reader (the header is
:mod:`.ply_header`, the writer :mod:`.ply_write`).

The vertex element holds one splat per row with (at least) the properties

    x y z  f_dc_0..2  opacity  scale_0..2 (scale_0..1 for 2DGS surfels)  rot_0..3 (w, x, y, z)

plus optional ``f_rest_*`` (0, 9, 24 or 45 of them, channel-major) and anything else (``nx ny
nz``, a ``label``): kept as the scene's :attr:`~splatgl.scene.splats.Scene.extras`, in their
stored types, which the writer writes again.  Values are the raw training values (log-scales, opacity logits,
unnormalised quaternions); :func:`splatgl.scene.splats.activate` validates them.

Other elements may precede or follow the vertex element.  In binary files they are skipped by
size, so they must hold fixed-size scalar properties only; an element with a list property
before the vertex element is an error, one after it is ignored.  The PlayCanvas compressed PLY
(``element chunk`` with packed properties) belongs to :mod:`splatgl.formats.compressed_ply`.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from ..scene.splats import Scene, SplatKind, activate, sh_degree_from_rest_count
from ._memory import check_memory
from ._messages import quote, reader_guard
from .ply_header import SCALAR_TYPES, Element, Header, _error, parse_header

NAME = "ply"
EXTENSIONS = (".ply",)

_REST_RE = re.compile(r"^f_rest_(\d+)$")
#: Rows per read of a binary PLY (64 Ki rows: 16 MiB for 62 float properties).
CHUNK_ROWS = 1 << 16


def sniff(head: bytes) -> bool:
    """True for a ``ply`` header with an ``element vertex`` holding a float ``x`` and no
    ``element chunk`` (the compressed PLY is another format)."""
    if not (head.startswith(b"ply\n") or head.startswith(b"ply\r\n")):
        return False
    text = head.split(b"end_header", 1)[0].decode("ascii", errors="replace")
    current, has_x = None, False
    for line in text.splitlines():
        words = line.split()
        if len(words) >= 2 and words[0] == "element":
            current = words[1]
            if current == "chunk":
                return False
        elif len(words) == 3 and words[0] == "property" and current == "vertex":
            if words[2] == "x" and SCALAR_TYPES.get(words[1], "").startswith("f"):
                has_x = True
    return has_x


def _vertex_layout(path, header: Header, file_size: int) -> tuple[int, np.dtype]:
    """(byte offset, row dtype) of the binary vertex rows, all element sizes checked first.

    Other fixed-size elements are skipped by size; one with list properties may only follow the
    vertex element (it is then ignored, its size being unknown without parsing).
    """
    offset = header.body_offset
    found = None
    for elem in header.elements:
        if elem.has_list:
            if found is not None:
                return found  # after the vertex rows: ignored
            raise _error(path, f"element {quote(elem.name)} before the vertex element has list "
                               "properties; only fixed-size scalar properties are supported "
                               "in binary PLY", elem.name)
        dtype = elem.dtype(header.order)
        need = elem.count * dtype.itemsize
        if offset + need > file_size:
            raise _error(path, f"file is truncated: element {quote(elem.name)} needs {need} bytes "
                               f"({elem.count} rows x {dtype.itemsize} bytes) from byte {offset}"
                               f", found {max(0, file_size - offset)}", elem.name)
        if elem.name == "vertex":
            found = (offset, dtype)
        offset += need
    if offset < file_size:
        raise _error(path, f"{file_size - offset} bytes after the last element "
                           f"(header declares {offset} bytes in all); header/count mismatch")
    return found


def _read_rows_chunked(path, fh, offset: int, dtype: np.dtype, count: int, plan: "_Columns",
                       progress, what: str) -> None:
    """Read ``count`` binary rows from ``offset`` into ``plan``'s arrays, CHUNK_ROWS at a time.

    One (CHUNK_ROWS,) structured buffer is reused (``readinto``), so the reader's memory is the
    decoded arrays plus one chunk; ``progress(done_rows, count, what)`` follows every chunk.
    """
    fh.seek(offset)
    buf = np.empty(min(count, CHUNK_ROWS), dtype)
    done = 0
    if progress is not None:
        progress(0, count, what)
    while done < count:
        rows = buf[:min(CHUNK_ROWS, count - done)]
        view = memoryview(rows.view(np.uint8))
        got = 0
        while got < view.nbytes:
            n = fh.readinto(view[got:])
            if not n:
                raise _error(path, f"file is truncated: vertex row {done + got // dtype.itemsize}"
                                   " could not be read", "vertex")
            got += n
        plan.fill(rows, done)
        done += rows.shape[0]
        if progress is not None:
            progress(done, count, what)


def _read_vertex_ascii(path, fh, header: Header) -> np.ndarray:
    """The vertex rows of an ASCII PLY as a structured array (native byte order)."""
    lines = fh.read().decode("ascii", errors="replace").splitlines()
    pos, vertex = 0, None
    for elem in header.elements:
        rows = lines[pos:pos + elem.count]
        if len(rows) < elem.count:
            raise _error(path, f"file is truncated: element {quote(elem.name)} declares {elem.count} "
                               f"rows, found {len(rows)} (file ends at line "
                               f"{header.lines + len(lines)})", elem.name)
        if elem.name == "vertex":
            vertex = _parse_ascii_rows(path, elem, rows, header.lines + pos + 1)
        pos += elem.count
    extra = sum(1 for line in lines[pos:] if line.strip())
    if extra:
        raise _error(path, f"{extra} non-empty line(s) after the last element "
                           f"(from line {header.lines + pos + 1}); header/count mismatch")
    return vertex


def _parse_ascii_rows(path, elem: Element, rows: list[str], first_line: int) -> np.ndarray:
    nprop = len(elem.properties)
    tokens = " ".join(rows).split()
    if len(tokens) != nprop * elem.count:
        for i, row in enumerate(rows):
            if len(row.split()) != nprop:
                raise _error(path, f"line {first_line + i}: {len(row.split())} values, expected "
                                   f"{nprop} (one per vertex property)", elem.name)
    try:
        values = np.array(tokens, dtype=np.float64).reshape(elem.count, nprop)
    except ValueError:
        for i, row in enumerate(rows):
            for tok, (name, _) in zip(row.split(), elem.properties):
                try:
                    float(tok)
                except ValueError:
                    raise _error(path, f"line {first_line + i}: {quote(tok)} is not a number",
                                 name) from None
        raise
    out = np.empty(elem.count, elem.dtype("="))
    for j, (name, _) in enumerate(elem.properties):
        out[name] = values[:, j]
    return out


class _Columns:
    """Where each vertex property goes in the decoded float32 arrays (the :func:`activate` inputs).

    ``means`` (N, 3) x y z; ``dc`` into ``sh[:, 0]``; ``opacity`` (N,); ``log_scales`` (N, 3) or
    (N, 2) for surfels; ``quats`` (N, 4) rot_0..3 (w, x, y, z); ``f_rest_*`` (channel-major in
    the file) into ``sh[:, 1:]`` (N, K - 1, 3).  Checks the required properties on creation.
    """

    def __init__(self, path, names: list[str], count: int, dtype: np.dtype | None = None):
        have = set(names)
        surfel = "scale_1" in have and "scale_2" not in have
        self.surfel = surfel
        nscale = 2 if surfel else 3
        groups = [("means", ["x", "y", "z"]), ("dc", [f"f_dc_{i}" for i in range(3)]),
                  ("opacity", ["opacity"]), ("log_scales", [f"scale_{i}" for i in range(nscale)]),
                  ("quats", [f"rot_{i}" for i in range(4)])]
        for _, group in groups:
            missing = [n for n in group if n not in have]
            if missing:
                raise _error(path, "required vertex property missing (has: "
                                   f"{quote(' '.join(names), 200)})", missing[0])
        rest_idx = sorted(int(m.group(1)) for n in names if (m := _REST_RE.match(n)))
        if rest_idx != list(range(len(rest_idx))):
            gap = next(i for i in range(len(rest_idx) + 1) if i not in rest_idx)
            raise _error(path, f"f_rest properties are not numbered 0..{len(rest_idx) - 1}",
                         f"f_rest_{gap}")
        degree = sh_degree_from_rest_count(path, len(rest_idx))
        k = (degree + 1) ** 2
        self.means = np.empty((count, 3), np.float32)
        self.quats = np.empty((count, 4), np.float32)
        self.log_scales = np.empty((count, nscale), np.float32)
        self.opacity = np.empty(count, np.float32)
        self.sh = np.empty((count, k, 3), np.float32)
        #: (property name, target array, index within a row of the target)
        self.targets: list[tuple[str, np.ndarray, tuple]] = []
        for (key, group) in groups:
            for i, name in enumerate(group):
                if key == "dc":
                    self.targets.append((name, self.sh, (0, i)))
                elif key == "opacity":
                    self.targets.append((name, self.opacity, ()))
                else:
                    self.targets.append((name, getattr(self, key), (i,)))
        for j in rest_idx:  # channel-major: f_rest_{c (K-1) + m} is coefficient m + 1 of c
            c, m = divmod(j, k - 1)
            self.targets.append((f"f_rest_{j}", self.sh, (m + 1, c)))
        used = {name for name, _, _ in self.targets}
        others = [(n, dtype[n].newbyteorder("=")) for n in names if n not in used and
                  dtype is not None]
        #: every other property, in its stored type (None when there is none, or only normals
        #: that are all zero: the INRIA placeholders, allocated on the first that is not)
        self.extra_dtype = np.dtype(others) if others else None
        only_normals = all(n in ("nx", "ny", "nz") for n, _ in others)
        self.extras = np.zeros(count, self.extra_dtype) if others and not only_normals else None

    def freeze(self) -> None:
        """Mark the arrays read-only: nothing else holds them, so a scene may adopt them."""
        for arr in (self.means, self.quats, self.log_scales, self.opacity, self.sh, self.extras):
            if arr is not None:
                arr.flags.writeable = False

    def fill(self, rows: np.ndarray, start: int) -> None:
        """Copy the structured ``rows`` (any scalar types, either byte order) to ``start:``."""
        stop = start + rows.shape[0]
        for name, target, index in self.targets:
            target[(slice(start, stop),) + index] = rows[name]
        if self.extras is None and self.extra_dtype is not None and any(
                np.any(rows[n] != 0) for n in self.extra_dtype.names):
            self.extras = np.zeros(self.means.shape[0], self.extra_dtype)  # rows before: zeros
        for name in self.extras.dtype.names if self.extras is not None else ():
            self.extras[name][start:stop] = rows[name]


def _sh_coeffs(names: list[str]) -> int:
    """SH coefficients per channel the ``f_rest_*`` properties imply (for the memory estimate;
    :class:`_Columns` checks the count exactly)."""
    return sum(1 for n in names if _REST_RE.match(n)) // 3 + 1


@reader_guard
def read(path: Path, drop_invalid: bool = False, progress=None, allow_empty: bool = False) -> Scene:
    """Load an INRIA-style PLY into a :class:`Scene` (raw values kept, rows validated).

    Binary files are read :data:`CHUNK_ROWS` rows at a time straight into the float32 arrays the
    scene is built from, so memory beyond them is one chunk; ``progress(done_rows, total_rows,
    what)`` (see :mod:`splatgl.progress`) is called after every chunk when given.

    Raises :class:`SceneFormatError` naming the file and, where one is at fault, the property;
    a file of zero splats is refused unless ``allow_empty`` (see :func:`splatgl.load_scene`).
    """
    what = f"reading {Path(path).name}"
    try:
        with open(path, "rb") as fh:
            header = parse_header(path, fh)
            names = {e.name for e in header.elements}
            if len(names) != len(header.elements):
                raise _error(path, "the header declares an element name twice")
            if "vertex" not in names:
                raise _error(path, "the header has no 'element vertex'")
            vertex_elem = next(e for e in header.elements if e.name == "vertex")
            if "chunk" in names or any(n.startswith("packed_") for n, _ in
                                       vertex_elem.properties):
                raise _error(path, "this is a PlayCanvas compressed PLY (element chunk / packed "
                                   "properties), not an INRIA-style PLY")
            if vertex_elem.has_list:
                raise _error(path, "the vertex element has a list property", "vertex")
            count = vertex_elem.count
            prop_names = [n for n, _ in vertex_elem.properties]
            file_size = os.fstat(fh.fileno()).st_size
            if header.order is None:
                # ASCII: the text, its lines and one Python float object per token are held
                # at once (about 80 bytes per value), then the float64 rows.
                check_memory(path, count, _sh_coeffs(prop_names), 96 * len(prop_names),
                             3 * file_size, "vertex")
                vertex = _read_vertex_ascii(path, fh, header)
                _check_not_empty(path, count, allow_empty)
                plan = _Columns(path, prop_names, count, vertex.dtype)
                if progress is not None:
                    progress(0, count, what)
                plan.fill(vertex, 0)
                del vertex
                if progress is not None:
                    progress(count, count, what)
            else:
                offset, dtype = _vertex_layout(path, header, file_size)
                _check_not_empty(path, count, allow_empty)
                # binary: rows go straight into the float32 arrays through one chunk buffer
                check_memory(path, count, _sh_coeffs(prop_names), 0,
                             min(count, CHUNK_ROWS) * dtype.itemsize, "vertex")
                plan = _Columns(path, prop_names, count, dtype)
                _read_rows_chunked(path, fh, offset, dtype, count, plan, progress, what)
    except OSError as exc:
        raise _error(path, f"cannot read: {exc.strerror or exc}") from None
    kind = SplatKind.SURFEL_2D if plan.surfel else SplatKind.GAUSSIAN_3D
    plan.freeze()
    if count == 0:  # allowed: nothing to validate
        return Scene(plan.means, plan.quats, plan.log_scales, plan.opacity, plan.sh, kind,
                     extras=plan.extras)
    return activate(path, plan.means, plan.quats, plan.log_scales, plan.opacity, plan.sh, kind,
                    drop_invalid, plan.extras)


def _check_not_empty(path, count: int, allow_empty: bool = False) -> None:
    if count == 0 and not allow_empty:
        raise _error(path, "the scene has no splats (element vertex 0)", "vertex")
