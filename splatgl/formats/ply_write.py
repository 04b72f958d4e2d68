"""Writer of INRIA-style 3DGS / 2DGS PLY files (float32; binary little or big endian, or ASCII),
read back bit-identical by :mod:`.ply`; :func:`write_elements` writes any PLY of scalar
properties (the compressed PLY and the level-of-detail file use it too).

The vertex layout is :func:`scene_to_vertices`: ``x y z [nx ny nz] f_dc_0..2 f_rest_*
(channel-major) opacity scale_* rot_0..3``, the raw training values (log-scales, opacity
logits, quaternions as stored), then the scene's other per-splat properties
(:attr:`~splatgl.scene.splats.Scene.extras`, read from a PLY) in their stored types; its normals
take the place of the zeros.
"""

from __future__ import annotations

import numpy as np

from ..scene.splats import Scene, sh_to_rest
from .ply import EXTENSIONS, NAME  # noqa: F401 (the format registry reads them here too)
from .ply_header import SCALAR_TYPES

#: Rows per block of a binary write (one block's records exist at a time).
WRITE_BLOCK = 1 << 18


def write_elements(path, elements: list[tuple[str, np.ndarray]], byte_order: str = "little",
                   ascii: bool = False, comments: tuple[str, ...] = ()) -> None:
    """Write any PLY: ``elements`` is a list of ``(name, structured array)`` with scalar fields.

    ``byte_order`` is 'little' or 'big' (binary); ``ascii=True`` writes text with 9 significant
    digits for floats, enough for float32 to read back bit-exact.
    """
    order = "<" if byte_order == "little" else ">"
    with open(path, "wb") as fh:
        fh.write(_header([(name, len(arr), arr.dtype) for name, arr in elements], byte_order,
                         ascii, comments))
        for _, arr in elements:
            if ascii:
                fmts = ["%.9g" if arr.dtype[n].kind == "f" else "%d" for n in arr.dtype.names]
                cols = [arr[n] for n in arr.dtype.names]
                for row in zip(*cols):
                    fh.write((" ".join(f % v for f, v in zip(fmts, row)) + "\n").encode("ascii"))
            else:
                _ordered(arr, order).tofile(fh)


def _ordered(arr: np.ndarray, order: str) -> np.ndarray:
    """``arr`` with every field in byte ``order`` ("<" or ">"); no copy when it already is."""
    dt = np.dtype([(n, order + arr.dtype[n].str[1:]) for n in arr.dtype.names])
    return arr.astype(dt, copy=False)


def _header(elements, byte_order: str, ascii: bool, comments) -> bytes:
    """The PLY header of ``elements`` ``[(name, count, structured dtype)]``."""
    if byte_order not in ("little", "big"):
        raise ValueError(f"byte_order must be 'little' or 'big', not {byte_order!r}")
    fmt = "ascii" if ascii else f"binary_{byte_order}_endian"
    codes = {v: k for k, v in SCALAR_TYPES.items() if k.isalpha() and not k[-1].isdigit()}
    head = ["ply", f"format {fmt} 1.0", *(f"comment {c}" for c in comments)]
    for name, count, dtype in elements:
        head.append(f"element {name} {count}")
        for fname in dtype.names:
            head.append(f"property {codes[dtype[fname].str[1:]]} {fname}")
    head.append("end_header")
    return ("\n".join(head) + "\n").encode("ascii")


def scene_to_vertices(scene: Scene, normals: bool = True) -> np.ndarray:
    """The INRIA vertex layout of ``scene``: a structured float32 array, one row per splat.

    Fields: x y z [nx ny nz] f_dc_0..2 f_rest_* (channel-major) opacity scale_* rot_0..3, then
    the scene's extras (its own ``nx ny nz`` in their place, written even without ``normals``).
    """
    dc, rest = sh_to_rest(scene.sh)
    extras = scene.extras
    names = extras.dtype.names if extras is not None else ()
    cols: list[tuple[str, np.ndarray]] = [(n, scene.means[:, i]) for i, n in enumerate("xyz")]
    if all(n in names for n in ("nx", "ny", "nz")):
        cols += [(n, extras[n]) for n in ("nx", "ny", "nz")]
    elif normals and not {"nx", "ny", "nz"} & set(names):
        zero = np.zeros(scene.count, np.float32)
        cols += [("nx", zero), ("ny", zero), ("nz", zero)]
    cols += [(f"f_dc_{i}", dc[:, i]) for i in range(3)]
    cols += [(f"f_rest_{i}", rest[:, i]) for i in range(rest.shape[1])]
    cols.append(("opacity", scene.opacity_logits))
    cols += [(f"scale_{i}", scene.log_scales[:, i]) for i in range(scene.log_scales.shape[1])]
    cols += [(f"rot_{i}", scene.quats[:, i]) for i in range(4)]
    cols += [(n, extras[n]) for n in names if n not in {c for c, _ in cols}]
    out = np.empty(scene.count, np.dtype([(n, np.asarray(c).dtype.newbyteorder("<") if n in names
                                           else "<f4") for n, c in cols]))
    for n, c in cols:
        out[n] = c
    return out


def write(path, scene: Scene, *, byte_order: str = "little", ascii: bool = False,
          normals: bool = True) -> None:
    """Write ``scene`` as an INRIA-layout PLY (float32; binary little endian by default).

    Reading the file back gives bit-identical arrays.  ``byte_order='big'`` and ``ascii=True``
    exist mainly to exercise the reader; ``normals=False`` leaves out ``nx ny nz``.
    """
    comments = ("written by splatgl",)
    if ascii:
        write_elements(path, [("vertex", scene_to_vertices(scene, normals))], byte_order, ascii,
                       comments=comments)
        return
    # Binary: the rows in blocks, so a large scene is never held twice more as file records.
    dtype = scene_to_vertices(scene.subset(slice(0, 0)), normals).dtype
    order = "<" if byte_order == "little" else ">"
    with open(path, "wb") as fh:
        fh.write(_header([("vertex", scene.count, dtype)], byte_order, False, comments))
        for start in range(0, scene.count, WRITE_BLOCK):
            block = scene.subset(slice(start, start + WRITE_BLOCK))
            _ordered(scene_to_vertices(block, normals), order).tofile(fh)
