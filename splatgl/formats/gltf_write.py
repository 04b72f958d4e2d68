"""Writer of glTF 2.0 with ``KHR_gaussian_splatting`` (``.glb`` binary, ``.gltf`` JSON with the
buffer as a data URI), read back by :mod:`.gltf`.

The layout, the attributes and the axes (the scene's RDF turned 180 degrees about z into glTF's
LUF by :func:`splatgl.formats.gltf.turn`) are described in :mod:`splatgl.formats.gltf`.  Every
value is stored as float32: linear scales, opacity in [0, 1], the unit quaternion in glTF order
(x, y, z, w) and the SH coefficients, so the round trip loses only float32 rounding
(:func:`error_bounds`).
"""

from __future__ import annotations

import base64
import json
import struct
from pathlib import Path

import numpy as np

from ..errors import SceneFormatError
from ..scene.splats import Scene, SplatKind
from . import quantise as qz
from .gltf import CHUNK_BIN, CHUNK_JSON, EXT, GLB_MAGIC, PREFIX, turn
from .gltf import EXTENSIONS, NAME  # noqa: F401 (the format registry reads them here too)

#: What the writer states in the extension object.
EXTENSION_OBJECT = {"kernel": "ellipse", "colorSpace": "srgb_rec709_display",
                    "projection": "perspective", "sortingMethod": "cameraDistance"}


def document(scene: Scene, path=None) -> tuple[dict, bytes]:
    """The glTF JSON object (buffer 0 without uri) and the binary buffer of ``scene``."""
    if scene.kind is not SplatKind.GAUSSIAN_3D:
        raise SceneFormatError(path, "KHR_gaussian_splatting stores 3D Gaussians only; cannot "
                                     "write a 2DGS surfel scene (write .ply instead)", "scale")
    qz.check_linear_scales(scene, path, "glTF")
    means, quats, _, _, sh = turn(scene.means.astype(np.float64),
                                   scene.rotations.astype(np.float64), None, None, scene.sh)
    columns = [("POSITION", means.astype(np.float32), "VEC3"),
               (PREFIX + "ROTATION", quats[:, [1, 2, 3, 0]].astype(np.float32), "VEC4"),
               (PREFIX + "SCALE", scene.scales, "VEC3"),
               (PREFIX + "OPACITY", scene.opacities, "SCALAR")]
    k = 0
    for degree in range(scene.sh_degree + 1):
        for n in range(2 * degree + 1):
            columns.append((f"{PREFIX}SH_DEGREE_{degree}_COEF_{n}", sh[:, k], "VEC3"))
            k += 1
    blobs, views, accessors, attributes, offset = [], [], [], {}, 0
    for i, (name, values, kind) in enumerate(columns):
        blob = np.ascontiguousarray(values, "<f4").tobytes()
        views.append({"buffer": 0, "byteOffset": offset, "byteLength": len(blob), "target": 34962})
        acc = {"bufferView": i, "componentType": 5126, "count": scene.count, "type": kind}
        if name == "POSITION":
            acc["min"] = values.min(axis=0).tolist()
            acc["max"] = values.max(axis=0).tolist()
        accessors.append(acc)
        attributes[name] = i
        blobs.append(blob + b"\0" * (-len(blob) % 4))
        offset += len(blobs[-1])
    binary = b"".join(blobs)
    gltf = {"asset": {"version": "2.0", "generator": "splatgl"},
            "extensionsUsed": [EXT], "scene": 0, "scenes": [{"nodes": [0]}],
            "nodes": [{"mesh": 0}],
            "meshes": [{"primitives": [{"attributes": attributes, "mode": 0,
                                        "extensions": {EXT: dict(EXTENSION_OBJECT)}}]}],
            "buffers": [{"byteLength": len(binary)}], "bufferViews": views,
            "accessors": accessors}
    return gltf, binary


def write(path, scene: Scene, target=None) -> None:
    """Write ``scene`` to ``path`` as GLB, or as ``.gltf`` JSON with the buffer as a base64 data
    URI (chosen by the file's name ``target``, default ``path``: ``path`` may be a temporary)."""
    path = Path(path)
    target = Path(target) if target is not None else path
    gltf, binary = document(scene, target)
    if target.name.lower().endswith(".gltf"):
        gltf["buffers"][0]["uri"] = ("data:application/octet-stream;base64,"
                                     + base64.b64encode(binary).decode("ascii"))
        path.write_text(json.dumps(gltf), encoding="utf-8")
        return
    text = json.dumps(gltf).encode("utf-8")
    text += b" " * (-len(text) % 4)
    total = 12 + 8 + len(text) + 8 + len(binary)
    with open(path, "wb") as fh:
        fh.write(struct.pack("<4sII", GLB_MAGIC, 2, total))
        fh.write(struct.pack("<II", len(text), CHUNK_JSON) + text)
        fh.write(struct.pack("<II", len(binary), CHUNK_BIN) + binary)


def error_bounds(scene: Scene) -> dict:
    """Round-trip bounds: float32 storage of linear scale, opacity and the unit quaternion."""
    max_log = float(np.abs(scene.log_scales).max()) if scene.count else 0.0
    return {
        "position": qz.position_slack(scene.means),
        "scale": 8.0 * 2.0 ** -24 * (1.0 + max_log),
        "opacity": 1e-6,
        "rotation": 1e-3,
        "color": 1e-7,
        "sh_rest": 1e-7 if scene.sh_degree > 0 else None,
    }
