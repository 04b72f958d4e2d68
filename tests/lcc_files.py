"""Writing XGrids LCC test files from the white paper's layout (github.com/xgrids/LCCWhitepaper),
independently of splatgl's reader (splatgl.formats.lcc): ``meta.lcc``, ``Index.bin``,
``Data.bin``, ``Shcoef.bin`` (SH degree 3 scenes) and optionally ``Environment.bin``.

Levels are given as scenes in PLY axes (level 0 the finest); each is turned into LCC's axes
(the inverse of what splat-transform applies when it reads LCC), cut into a grid of units by
x and y, and quantised as the white paper says.  ``lower=True`` names the binary files in lower
case (``data.bin``: what splat-transform 3.7.0 opens).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

SH_C0 = 0.28209479177387814
#: PLY axes -> LCC axes: the inverse of the turn splat-transform applies on reading LCC (its
#: Euler angles (90, 0, 180) and PLY's (0, 0, 180)), written out here.
FROM_PLY = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])  # (x, z, -y)


def _sh_turn(rot: np.ndarray) -> np.ndarray:
    from splatgl.formats.lcc import _sh_rotation  # the fitted SH rotation (checked elsewhere)
    return _sh_rotation(rot, 3)


def _quat(r: np.ndarray) -> np.ndarray:
    from splatgl.scene.quaternion import rotmat_to_quat
    return rotmat_to_quat(r[None])[0]


def _records(scene, scale_range, sh_range) -> tuple[bytes, bytes | None]:
    from splatgl.scene.quaternion import quat_multiply

    n = scene.count
    pos = scene.means.astype(np.float64) @ FROM_PLY.T
    q = quat_multiply(np.broadcast_to(_quat(FROM_PLY), (n, 4)), scene.rotations.astype(np.float64))
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    xyzw = q[:, [1, 2, 3, 0]]
    largest = np.abs(xyzw).argmax(1)
    xyzw = xyzw * np.where(xyzw[np.arange(n), largest] < 0, -1.0, 1.0)[:, None]
    # the white paper's QLut: idx 0 puts w (the decoded 4th) first, ... idx 3 last
    rest = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])[largest]
    abc = xyzw[np.arange(n)[:, None], rest]
    u = np.clip(np.rint((abc + math.sqrt(0.5)) / math.sqrt(2) * 1023), 0, 1023).astype(np.uint32)
    rot = u[:, 0] | (u[:, 1] << 10) | (u[:, 2] << 20) | (largest.astype(np.uint32) << 30)
    rec = np.zeros(n, np.dtype([("pos", "<f4", 3), ("rgba", "u1", 4), ("scale", "<u2", 3),
                                ("rot", "<u4"), ("normal", "<u2", 3)]))
    rec["pos"] = pos
    color = np.clip(np.rint((scene.sh[:, 0].astype(np.float64) * SH_C0 + 0.5) * 255), 0, 255)
    rec["rgba"][:, :3] = color
    rec["rgba"][:, 3] = np.clip(np.rint(scene.opacities * 255), 0, 255)
    lo, hi = scale_range
    scales = scene.scales.astype(np.float64)  # per splat axis: the turn leaves them
    rec["scale"] = np.clip(np.rint((scales - lo) / (hi - lo) * 65535), 0, 65535)
    rec["rot"] = rot
    sh = None
    if scene.sh_degree == 3:
        coeffs = np.einsum("kj,njc->nkc", _sh_turn(FROM_PLY), scene.sh.astype(np.float64))[:, 1:]
        a, b = sh_range
        t = (coeffs - a) / (b - a)
        words = (np.clip(np.rint(t[..., 0] * 2047), 0, 2047).astype(np.uint32)
                 | (np.clip(np.rint(t[..., 1] * 1023), 0, 1023).astype(np.uint32) << 11)
                 | (np.clip(np.rint(t[..., 2] * 2047), 0, 2047).astype(np.uint32) << 21))
        sh = np.concatenate([words, np.zeros((n, 1), np.uint32)], 1).astype("<u4").tobytes()
    return rec.tobytes(), sh


def write_lcc(folder: Path, levels: list, cells: int = 2, environment=None, lower: bool = False,
              name: str = "meta.lcc") -> Path:
    """Write ``levels`` (scenes, PLY axes, the same SH degree: 0 or 3) as LCC into ``folder``
    with a ``cells`` x ``cells`` grid of units; returns the ``meta.lcc`` path."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    quality = levels[0].sh_degree == 3
    allp = np.concatenate([lv.means.astype(np.float64) @ FROM_PLY.T for lv in levels])
    lo, hi = allp.min(0), allp.max(0) + 1e-6
    cell = (hi[:2] - lo[:2]) / cells
    every = [lv for lv in levels] + ([environment] if environment is not None else [])
    scales = np.concatenate([lv.scales for lv in every]).astype(np.float64)
    scale_range = (scales.min(0), scales.max(0) + 1e-9)
    sh_range = None
    if quality:
        rest = np.concatenate([np.einsum("kj,njc->nkc", _sh_turn(FROM_PLY),
                                         lv.sh.astype(np.float64))[:, 1:] for lv in every])
        sh_range = (rest.min((0, 1)), rest.max((0, 1)) + 1e-9)
    # units: which cell each splat of each level falls in
    keys = [np.clip(((lv.means.astype(np.float64) @ FROM_PLY.T)[:, :2] - lo[:2]) // cell, 0,
                    cells - 1).astype(int) for lv in levels]
    data, shdata, index = bytearray(), bytearray(), bytearray()
    for x in range(cells):
        for y in range(cells):
            entry = np.array([x, y], "<i2").tobytes()
            for lv, key in zip(levels, keys):
                rows = np.flatnonzero((key[:, 0] == x) & (key[:, 1] == y))
                rec, sh = _records(lv.subset(rows), scale_range, sh_range) if rows.size else (b"", b"")
                entry += np.array([rows.size], "<u4").tobytes() + np.array([len(data)], "<u8").tobytes()
                entry += np.array([len(rec)], "<u4").tobytes()
                data += rec
                shdata += sh or b""
            index += entry
    names = {"index": "Index.bin", "data": "Data.bin", "sh": "Shcoef.bin", "env": "Environment.bin"}
    if lower:
        names = {k: v.lower() for k, v in names.items()}
    (folder / names["index"]).write_bytes(bytes(index))
    (folder / names["data"]).write_bytes(bytes(data))
    if quality:
        (folder / names["sh"]).write_bytes(bytes(shdata))
    if environment is not None:
        rec, sh = _records(environment, scale_range, sh_range)
        if sh is None:
            env = rec
        else:
            env = np.concatenate([np.frombuffer(rec, np.uint8).reshape(-1, 32),
                                  np.frombuffer(sh, np.uint8).reshape(-1, 64)], 1).tobytes()
        (folder / names["env"]).write_bytes(env)
    attrs = [{"name": "scale", "min": scale_range[0].tolist(), "max": scale_range[1].tolist()},
             {"name": "envscale", "min": scale_range[0].tolist(), "max": scale_range[1].tolist()},
             {"name": "opacity", "min": [0.0], "max": [1.0]}]
    sh_lo, sh_hi = sh_range if quality else (np.zeros(3), np.zeros(3))  # listed either way
    attrs += [{"name": "shcoef", "min": sh_lo.tolist(), "max": sh_hi.tolist()},
              {"name": "envshcoef", "min": sh_lo.tolist(), "max": sh_hi.tolist()}]
    meta = {"version": "5.0", "name": "splatgl test", "source": "ply", "dataType": "None",
            "totalSplats": int(sum(lv.count for lv in levels)), "totalLevel": len(levels),
            "cellLengthX": float(cell[0]), "cellLengthY": float(cell[1]),
            "indexDataSize": 4 + 16 * len(levels), "offset": [0, 0, 0], "epsg": 0,
            "shift": [0, 0, 0], "scale": [1, 1, 1], "splats": [int(lv.count) for lv in levels],
            "boundingBox": {"min": lo.tolist(), "max": hi.tolist()}, "encoding": "COMPRESS",
            "fileType": "Quality" if quality else "Portable", "attributes": attrs}
    path = folder / name
    path.write_text(json.dumps(meta, indent=1))
    return path
