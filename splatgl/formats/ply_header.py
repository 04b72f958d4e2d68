"""The PLY header: scalar property types, elements, and parsing the header of a file.

Shared by the INRIA PLY reader (:mod:`.ply`) and writer (:mod:`.ply_write`), the level-of-detail
file (:mod:`splatgl.lod.io`) and the completeness check of written files
(:mod:`splatgl.formats.written`).  A header is ``ply``, one ``format`` line (binary little or big
endian, or ASCII, version 1.0), ``element NAME COUNT`` lines each followed by its ``property
TYPE NAME`` (or ``property list COUNT_TYPE ITEM_TYPE NAME``) lines, ``comment`` / ``obj_info``
lines anywhere, and ``end_header``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import SceneFormatError
from ._messages import quote

#: PLY scalar type names (both spellings) -> NumPy type codes without byte order.
SCALAR_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
#: ``format`` keyword -> NumPy byte order (None for ASCII).
FORMATS = {"binary_little_endian": "<", "binary_big_endian": ">", "ascii": None}
#: A header longer than this is not a PLY header (guards against reading a huge text file).
MAX_HEADER_BYTES = 1 << 20


@dataclass
class Element:
    """One ``element`` of the header: its name, row count and properties.

    ``properties`` is a list of ``(name, numpy_code)``; ``has_list`` is set when any property is a
    ``property list`` (variable size per row).
    """

    name: str
    count: int
    properties: list[tuple[str, str]] = field(default_factory=list)
    has_list: bool = False

    def dtype(self, order: str) -> np.dtype:
        """Structured dtype of one row in byte ``order`` ('<' or '>'); fixed-size rows only."""
        return np.dtype([(name, order + code) for name, code in self.properties])


@dataclass
class Header:
    """A parsed PLY header: byte order (None for ASCII), elements, and where the body starts."""

    order: str | None
    elements: list[Element]
    body_offset: int
    lines: int  # number of header lines, so ASCII errors can give file line numbers


def _error(path, message: str, field_name: str | None = None) -> SceneFormatError:
    return SceneFormatError(path, message, field_name)


def parse_header(path, fh) -> Header:
    """Parse the header from the binary file object ``fh`` (positioned at 0).

    Raises :class:`SceneFormatError` for a missing ``ply`` magic, missing ``end_header``,
    unsupported format, unknown property types and malformed lines.
    """
    first = fh.readline(16)
    if first.rstrip(b"\r\n") != b"ply":
        raise _error(path, "not a PLY file (it does not start with a 'ply' line)")
    order: str | None = None
    have_format = False
    elements: list[Element] = []
    lineno = 1
    while True:
        raw = fh.readline(MAX_HEADER_BYTES)
        lineno += 1
        if not raw:
            raise _error(path, "the header has no 'end_header' line (file ends inside the header)")
        if fh.tell() > MAX_HEADER_BYTES:
            raise _error(path, f"no 'end_header' within the first {MAX_HEADER_BYTES} bytes")
        try:
            line = raw.decode("ascii").strip()
        except UnicodeDecodeError:
            raise _error(path, f"header line {lineno} is not ASCII text (missing 'end_header'?)")
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        key = words[0]
        if key == "end_header":
            break
        if key == "format":
            if len(words) != 3 or words[1] not in FORMATS or words[2] != "1.0":
                raise _error(path, f"unsupported format line {quote(line)} (expected "
                                   "'format binary_little_endian|binary_big_endian|ascii 1.0')",
                             "format")
            order, have_format = FORMATS[words[1]], True
        elif key == "element":
            if len(words) != 3 or not words[2].isdigit():
                raise _error(path, f"header line {lineno}: malformed element line {quote(line)}")
            elements.append(Element(words[1], int(words[2])))
        elif key == "property":
            if not elements:
                raise _error(path, f"header line {lineno}: property before any element")
            elem = elements[-1]
            if len(words) == 5 and words[1] == "list":
                for t in words[2:4]:
                    if t not in SCALAR_TYPES:
                        raise _error(path, f"unknown property type {quote(t)} in list property",
                                     words[4])
                elem.has_list = True
                elem.properties.append((words[4], "list"))
            elif len(words) == 3:
                if words[1] not in SCALAR_TYPES:
                    raise _error(path, f"unknown property type {quote(words[1])} (expected one of "
                                       f"{', '.join(sorted(set(SCALAR_TYPES)))})", words[2])
                if any(words[2] == name for name, _ in elem.properties):
                    raise _error(path, f"property declared twice in element {quote(elem.name)}",
                                 words[2])
                elem.properties.append((words[2], SCALAR_TYPES[words[1]]))
            else:
                raise _error(path, f"header line {lineno}: malformed property line {quote(line)}")
        else:
            raise _error(path, f"header line {lineno}: unexpected header line {quote(line)}")
    if not have_format:
        raise _error(path, "the header has no 'format' line", "format")
    return Header(order, elements, fh.tell(), lineno)
