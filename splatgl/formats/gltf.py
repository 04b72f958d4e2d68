"""glTF 2.0 (``.glb`` binary, ``.gltf`` JSON) with ``KHR_gaussian_splatting``: reader (the writer
is :mod:`splatgl.formats.gltf_write`).

A splat primitive (``mode`` 0, POINTS) carries the extension object (``kernel``, ``colorSpace``,
optional ``projection`` / ``sortingMethod``) and the attributes

=============================================  ======  ==========================================
``POSITION``                                   VEC3    mean (glTF axes)
``KHR_gaussian_splatting:ROTATION``            VEC4    unit quaternion, glTF order (x, y, z, w)
``KHR_gaussian_splatting:SCALE``               VEC3    linear scales (not log)
``KHR_gaussian_splatting:OPACITY``             SCALAR  opacity in [0, 1] (not a logit)
``KHR_gaussian_splatting:SH_DEGREE_0_COEF_0``  VEC3    SH DC (colour = 0.5 + SH_C0 f_dc)
``KHR_gaussian_splatting:SH_DEGREE_l_COEF_n``  VEC3    degree l = 1..3, n = 0..2l (m = -l..l)
=============================================  ======  ==========================================

The SH basis order per degree (m = -l..l) is the 3DGS ``f_rest`` order, so coefficients map one to
one.  Accessors may be float or (normalised) integer where the extension allows it.

Axes: glTF is right-handed +Y up (Niantic's spec calls it LUF: left, up, front); 3DGS PLY (and
:class:`~splatgl.scene.splats.Scene`) is RDF (right, down, front).  RDF -> LUF is a 180-degree turn about
z: ``(x, y, z) -> (-x, -y, z)``, the rotation composed with that turn (``q -> (0, 0, 0, 1) q``:
``(w, x, y, z) -> (-z, -y, x, w)``) and the SH coefficients odd in ``(x, y)`` negated
(:data:`Z180_SH_SIGNS`).  splat-transform and the PlayCanvas engine use the same turn between
PLY and glTF (their quaternions match these bit for bit).  Turning twice gives ``-q``, the same
rotation, so reading and writing (:mod:`.gltf_write`) share :func:`turn`.

``KHR_gaussian_splatting_compression_spz_2`` (reading only): the primitive's extension object
holds ``extensions.KHR_gaussian_splatting_compression_spz_2.bufferView``, an SPZ blob whose
internal axes are SPZ's RUB; RUB -> RDF is decoded by :func:`splatgl.formats.spz.decode`.

Node transforms (TRS or matrix) are applied to means, rotations and scales; a rotating node is
refused for SH degree > 0 (rotating SH coefficients is not implemented), as is a non-uniform scale.
"""

from __future__ import annotations

import base64
import json
import math
from pathlib import Path

import numpy as np

from ..constants import SH_C0
from ..errors import SceneFormatError
from ..scene.json_text import unique_keys
from ..scene.quaternion import quat_multiply, quat_to_rotmat, rotmat_to_quat
from ..scene.splats import Scene, SplatKind, activate
from . import _binary, spz

NAME = "gltf"
EXTENSIONS = (".glb", ".gltf")
EXT = "KHR_gaussian_splatting"
EXT_SPZ = "KHR_gaussian_splatting_compression_spz_2"
PREFIX = EXT + ":"
GLB_MAGIC = b"glTF"
CHUNK_JSON = 0x4E4F534A
CHUNK_BIN = 0x004E4942
#: SH sign changes of the 180-degree turn about z, coefficients 1..15 (3DGS order).
Z180_SH_SIGNS = np.array([-1, 1, -1, 1, -1, 1, -1, 1, -1, 1, -1, 1, -1, 1, -1], np.float32)
#: The turn's effect on (x, y, z); on a quaternion (w, x, y, z) it is (-z, -y, x, w).
Z180_AXES = np.array([-1.0, -1.0, 1.0])
Z180_QUAT_ORDER = [3, 2, 1, 0]
Z180_QUAT_SIGNS = np.array([-1.0, -1.0, 1.0, 1.0])

_COMPONENTS = {5120: "i1", 5121: "u1", 5122: "i2", 5123: "u2", 5125: "u4", 5126: "f4"}
_TYPES = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


def sniff(head: bytes) -> bool:
    """GLB magic, or JSON with an ``asset`` key that names the extension."""
    if head.startswith(GLB_MAGIC):
        return True
    return head.lstrip().startswith(b"{") and b'"asset"' in head and EXT.encode() in head


class _Document:
    """A parsed glTF: the JSON object and its buffers (bytes)."""

    def __init__(self, path: Path):
        self.path = path
        data = _binary.read_bytes(path)
        binary = None
        if data.startswith(GLB_MAGIC):
            magic, version, length = _binary.unpack(path, "<4sII", data, 0, "GLB header")
            if version != 2:
                raise SceneFormatError(path, f"GLB version {version}, expected 2", "version")
            if length > len(data):
                raise SceneFormatError(path, f"truncated: GLB header says {length} bytes, file "
                                             f"has {len(data)}", "length")
            chunks, offset = {}, 12
            while offset + 8 <= length:
                size, kind = _binary.unpack(path, "<II", data, offset, "GLB chunk header")
                _binary.need(path, data, offset + 8, size, "GLB chunk")
                chunks.setdefault(kind, data[offset + 8:offset + 8 + size])
                offset += 8 + size + (-size % 4 if offset + 8 + size < length else 0)
            if CHUNK_JSON not in chunks:
                raise SceneFormatError(path, "GLB has no JSON chunk", "chunks")
            text, binary = chunks[CHUNK_JSON], chunks.get(CHUNK_BIN)
        else:
            text = data
        try:
            self.json = json.loads(text.decode("utf-8"), object_pairs_hook=unique_keys)
        except (UnicodeDecodeError, ValueError, RecursionError) as exc:
            raise SceneFormatError(path, f"glTF JSON is not valid: {exc}") from None
        if not isinstance(self.json, dict):
            raise SceneFormatError(path, "glTF JSON is not an object")
        self.binary = binary
        self._buffers: dict[int, bytes] = {}

    def item(self, key: str, index) -> dict:
        items = self.json.get(key)
        if not isinstance(items, list) or not isinstance(index, int) or not 0 <= index < len(items) \
                or not isinstance(items[index], dict):
            raise SceneFormatError(self.path, f"no {key}[{index!r}]", key)
        return items[index]

    def buffer(self, index: int) -> bytes:
        if index not in self._buffers:
            buf = self.item("buffers", index)
            uri = buf.get("uri")
            if uri is None:
                if index != 0 or self.binary is None:
                    raise SceneFormatError(self.path, f"buffers[{index}] has no uri and no GLB "
                                                      "binary chunk", "buffers")
                blob = self.binary
            elif isinstance(uri, str) and uri.startswith("data:"):
                try:
                    blob = base64.b64decode(uri.split(",", 1)[1], validate=True)
                except (IndexError, ValueError):
                    raise SceneFormatError(self.path, f"buffers[{index}]: bad data URI",
                                           "uri") from None
            elif isinstance(uri, str) and uri and ".." not in Path(uri).parts \
                    and not Path(uri).is_absolute() and ":" not in uri:
                blob = _binary.read_bytes(self.path.parent / uri)
            else:
                raise SceneFormatError(self.path, f"buffers[{index}]: unsupported uri {uri!r}",
                                       "uri")
            self._buffers[index] = blob
        return self._buffers[index]

    def view(self, index) -> tuple[bytes, int, int, int | None]:
        """(buffer bytes, offset, length, stride) of bufferView ``index``, bounds-checked."""
        view = self.item("bufferViews", index)
        data = self.buffer(view.get("buffer"))
        offset, length = view.get("byteOffset", 0), view.get("byteLength")
        if not all(isinstance(v, int) and v >= 0 for v in (offset, length)):
            raise SceneFormatError(self.path, f"bufferViews[{index}]: bad byteOffset/byteLength",
                                   "bufferViews")
        _binary.need(self.path, data, offset, length, f"bufferViews[{index}]", "bufferViews")
        return data, offset, length, view.get("byteStride")

    def accessor(self, index, count: int | None = None) -> np.ndarray:
        """(count, components) float64 values of accessor ``index`` (normalised ints decoded)."""
        acc = self.item("accessors", index)
        where = f"accessors[{index}]"
        if "sparse" in acc:
            raise SceneFormatError(self.path, "sparse accessors are not supported", where)
        code = _COMPONENTS.get(acc.get("componentType"))
        width = _TYPES.get(acc.get("type"))
        n = acc.get("count")
        if code is None or width is None or not isinstance(n, int) or n <= 0:
            raise SceneFormatError(self.path, "bad componentType, type or count", where)
        if count is not None and n != count:
            raise SceneFormatError(self.path, f"count {n}, expected {count} (one per splat)", where)
        data, start, length, stride = self.view(acc.get("bufferView"))
        skip = acc.get("byteOffset", 0)
        item = np.dtype("<" + code)
        row = item.itemsize * width
        stride = stride or row
        if not isinstance(stride, int) or stride < row or stride % item.itemsize \
                or not isinstance(skip, int) or skip < 0 or (start + skip) % item.itemsize:
            raise SceneFormatError(self.path, f"bad byteStride {stride!r} or byteOffset {skip!r}",
                                   where)
        if skip + stride * (n - 1) + row > length:
            raise SceneFormatError(self.path, f"truncated: {n} elements do not fit the buffer view "
                                              f"of {length} bytes", where)
        raw = np.ndarray((n, width), item, data, start + skip, (stride, item.itemsize))
        values = raw.astype(np.float64)
        if acc.get("normalized") and code != "f4":
            top = float(np.iinfo(item).max)
            values = np.maximum(values / top, -1.0)
        return values


def _node_matrices(doc: _Document) -> list[tuple[int, np.ndarray]]:
    """(mesh index, 4x4 global matrix) of every node instancing a mesh (identity if no nodes)."""
    nodes = doc.json.get("nodes")
    if not isinstance(nodes, list) or not nodes:
        meshes = doc.json.get("meshes")
        return [(i, np.eye(4)) for i in range(len(meshes) if isinstance(meshes, list) else 0)]
    scenes = doc.json.get("scenes") or [{"nodes": list(range(len(nodes)))}]
    scene = scenes[doc.json.get("scene", 0)] if isinstance(scenes, list) else {}
    out, stack = [], [(i, np.eye(4)) for i in (scene.get("nodes") or [])
                      if isinstance(scene, dict)]
    seen = set()
    while stack:
        index, parent = stack.pop()
        if index in seen:
            raise SceneFormatError(doc.path, f"node {index!r} appears twice (a cycle?)", "nodes")
        seen.add(index)
        node = doc.item("nodes", index)
        world = parent @ _local_matrix(doc.path, node, index)
        if "mesh" in node:
            out.append((node["mesh"], world))
        stack.extend((child, world) for child in node.get("children", []))
    return out


def _local_matrix(path, node: dict, index) -> np.ndarray:
    try:
        if "matrix" in node:
            return np.asarray(node["matrix"], np.float64).reshape(4, 4).T  # column-major
        m = np.eye(4)
        x, y, z, w = np.asarray(node.get("rotation", [0, 0, 0, 1]), np.float64)
        m[:3, :3] = quat_to_rotmat(np.array([w, x, y, z], np.float64))
        m[:3, :3] *= np.asarray(node.get("scale", [1, 1, 1]), np.float64)[None, :]
        m[:3, 3] = np.asarray(node.get("translation", [0, 0, 0]), np.float64)
        return m
    except (TypeError, ValueError):
        raise SceneFormatError(path, f"nodes[{index}]: bad transform", "nodes") from None


def _primitive(doc: _Document, prim: dict, where: str) -> tuple[np.ndarray, ...]:
    """(means, quats wxyz, log_scales, logits, sh) of one splat primitive, in glTF axes."""
    ext = prim["extensions"][EXT]
    spz_ext = (ext.get("extensions") or {}).get(EXT_SPZ) if isinstance(ext, dict) else None
    if isinstance(spz_ext, dict):
        data, offset, length, _ = doc.view(spz_ext.get("bufferView"))
        means, quats, log_scales, logits, sh = spz.decode(doc.path, data[offset:offset + length],
                                                          axes="rub")
        return turn(np.asarray(means, np.float64), np.asarray(quats, np.float64),
                     log_scales, logits, sh)
    attrs = prim.get("attributes")
    if not isinstance(attrs, dict) or "POSITION" not in attrs:
        raise SceneFormatError(doc.path, "splat primitive has no POSITION", where)
    means = doc.accessor(attrs["POSITION"])
    n = means.shape[0]

    def get(name: str, width: int, required: bool = True):
        if name not in attrs:
            if required:
                raise SceneFormatError(doc.path, f"splat primitive lacks {name}", where)
            return None
        values = doc.accessor(attrs[name], n)
        if values.shape[1] != width:
            raise SceneFormatError(doc.path, f"{name} has {values.shape[1]} components, "
                                             f"expected {width}", where)
        return values

    xyzw = get(PREFIX + "ROTATION", 4)
    scales = get(PREFIX + "SCALE", 3)
    colour = get("COLOR_0", 4, required=False)
    opacity = get(PREFIX + "OPACITY", 1, required=colour is None)
    dc = get(PREFIX + "SH_DEGREE_0_COEF_0", 3, required=colour is None)
    if opacity is None:
        opacity = colour[:, 3:]
    if dc is None:
        dc = (colour[:, :3] - 0.5) / SH_C0
    coeffs = [dc]
    for degree in (1, 2, 3):
        names = [f"{PREFIX}SH_DEGREE_{degree}_COEF_{n_}" for n_ in range(2 * degree + 1)]
        present = [name in attrs for name in names]
        if not any(present):
            break
        if not all(present):
            raise SceneFormatError(doc.path, f"SH degree {degree} is partly defined", where)
        coeffs += [get(name, 3) for name in names]
    sh = np.stack(coeffs, axis=1)
    quats = xyzw[:, [3, 0, 1, 2]]
    with np.errstate(divide="ignore", invalid="ignore"):
        log_scales = _binary.log_of(scales)
    return means, quats, log_scales, _binary.logit(opacity[:, 0]), sh


def turn(means, quats, log_scales, logits, sh) -> tuple[np.ndarray, ...]:
    """The 180-degree turn about z between glTF (LUF) and PLY (RDF) axes (its own inverse)."""
    out_sh = np.array(sh, np.float32, copy=True)
    out_sh[:, 1:] *= Z180_SH_SIGNS[: sh.shape[1] - 1, None]
    return (means * Z180_AXES, quats[:, Z180_QUAT_ORDER] * Z180_QUAT_SIGNS, log_scales, logits,
            out_sh)


def _transform(path, parts, matrix: np.ndarray) -> tuple[np.ndarray, ...]:
    means, quats, log_scales, logits, sh = parts
    if np.allclose(matrix, np.eye(4), atol=1e-12):
        return parts
    m = matrix[:3, :3]
    lengths = np.linalg.norm(m, axis=0)
    if not np.allclose(lengths, lengths[0], rtol=1e-5) or lengths[0] <= 0:
        raise SceneFormatError(path, f"node scale {lengths.tolist()} is not uniform and positive",
                               "nodes")
    r = m / lengths[0]
    if np.linalg.det(r) < 0:
        raise SceneFormatError(path, "node transform mirrors (negative determinant)", "nodes")
    rotates = not np.allclose(r, np.eye(3), atol=1e-9)
    if rotates and sh.shape[1] > 1:
        raise SceneFormatError(path, "a rotating node transform with SH degree > 0 is not "
                                     "supported (the SH coefficients would need rotating)", "nodes")
    means = means @ m.T + matrix[:3, 3]
    if rotates:
        quats = quat_multiply(rotmat_to_quat(r), quats)
    return means, quats, log_scales + math.log(lengths[0]), logits, sh


def _splat_parts(doc: _Document) -> list[tuple[np.ndarray, ...]]:
    parts = []
    for mesh_index, matrix in _node_matrices(doc):
        mesh = doc.item("meshes", mesh_index)
        for p, prim in enumerate(mesh.get("primitives") or []):
            if isinstance(prim, dict) and EXT in (prim.get("extensions") or {}):
                where = f"meshes[{mesh_index}].primitives[{p}]"
                parts.append(_transform(doc.path, _primitive(doc, prim, where), matrix))
    return parts


def read(path: Path, drop_invalid: bool = False) -> Scene:
    """Load the splat primitives of a glTF / GLB file (all of them, concatenated)."""
    path = Path(path)
    doc = _Document(path)
    try:
        parts = _splat_parts(doc)
    except SceneFormatError:
        raise
    except (TypeError, AttributeError, KeyError, IndexError, ValueError) as exc:
        # JSON of the wrong shape where the spec wants an object, list or number
        raise SceneFormatError(path, f"malformed glTF structure ({type(exc).__name__}: "
                                     f"{str(exc)[:100]})") from None
    if not parts:
        raise SceneFormatError(path, f"no mesh primitive uses {EXT}", "extensions")
    degree = min(p[4].shape[1] for p in parts)
    cat = [np.concatenate([p[i] if i < 4 else p[4][:, :degree] for p in parts])
           for i in range(5)]
    means, quats, log_scales, logits, sh = turn(*cat)
    return activate(path, means, quats, np.asarray(log_scales, np.float32),
                    np.asarray(logits, np.float32), np.asarray(sh, np.float32),
                    SplatKind.GAUSSIAN_3D, drop_invalid)
