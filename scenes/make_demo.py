"""Build the bundled demo scene, ``scenes/demo.ply`` (run: ``python scenes/make_demo.py``).

The demo is made to expose convention bugs at a glance (world -y is up, as in COLMAP scenes):
- a flower of 12 elongated petals at 30-degree steps and a ring of 48 thin tangent needles, so
  anisotropic splats appear at many orientations (a y flip or a transposed covariance shows);
- a sphere shell of flattened splats whose degree-1..3 SH make the colour depend on the view
  direction: red where the view ray points to world +x, blue towards -x, greener towards +z
  (a wrong SH sign or axis swaps the sides);
- an axis marker (red +x, green +y (down), blue +z (away)) and an asymmetric "F" glyph, so a
  mirrored or rotated image is obvious.
Deterministic: running it twice writes identical bytes (a test checks the committed file).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

from splatgl.constants import SH_C0  # noqa: E402
from splatgl.formats import save_scene  # noqa: E402
from splatgl.scene.splats import Scene  # noqa: E402


def _quat_z(theta: np.ndarray) -> np.ndarray:
    """(N, 4) quaternions rotating by ``theta`` about the world z axis."""
    return np.stack([np.cos(theta / 2), 0 * theta, 0 * theta, np.sin(theta / 2)], -1)


def _quat_from_z_to(normals: np.ndarray) -> np.ndarray:
    """(N, 4) quaternions rotating local +z onto each unit normal (N, 3)."""
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(z, normals)
    s = np.linalg.norm(axis, axis=1)
    c = normals @ z
    half = np.arctan2(s, c) / 2
    axis = np.where(s[:, None] > 1e-9, axis / np.maximum(s, 1e-12)[:, None], [1.0, 0.0, 0.0])
    return np.concatenate([np.cos(half)[:, None], axis * np.sin(half)[:, None]], 1)


def _dc(rgb: np.ndarray) -> np.ndarray:
    """SH DC coefficients that give colour ``rgb`` (N, 3) from the front: (c - 0.5) / C0."""
    return (np.asarray(rgb, np.float64) - 0.5) / SH_C0


def _hue(h: np.ndarray) -> np.ndarray:
    """(N, 3) saturated colours around the hue wheel, h in [0, 1)."""
    k = (h[:, None] * 6.0 + np.array([0.0, 4.0, 2.0])) % 6.0
    return 0.9 - 0.75 * np.clip(np.minimum(k, 4.0 - k), 0.0, 1.0)


def build_demo() -> Scene:
    parts = []  # (means, quats, scales, opacities, dc)

    # Flower: 12 petals at 30-degree steps in the z = 0 plane.
    theta = np.arange(12) * (math.pi / 6)
    means = np.stack([1.2 * np.cos(theta), 1.2 * np.sin(theta), 0 * theta], -1)
    parts.append((means, _quat_z(theta), np.tile([0.42, 0.07, 0.07], (12, 1)),
                  np.full(12, 0.92), _dc(_hue(np.arange(12) / 12))))

    # Ring of thin needles, tangent to a circle of radius 1.9.
    phi = np.arange(48) * (2 * math.pi / 48)
    means = np.stack([1.9 * np.cos(phi), 1.9 * np.sin(phi), 0 * phi], -1)
    parts.append((means, _quat_z(phi + math.pi / 2), np.tile([0.12, 0.012, 0.012], (48, 1)),
                  np.full(48, 0.95), _dc(np.tile([0.95, 0.9, 0.7], (48, 1)))))

    # Sphere shell (Fibonacci lattice) of flattened splats with view-dependent SH.
    n = 1500
    i = np.arange(n) + 0.5
    polar = np.arccos(1 - 2 * i / n)
    azim = math.pi * (1 + 5 ** 0.5) * i
    normals = np.stack([np.sin(polar) * np.cos(azim), np.sin(polar) * np.sin(azim), np.cos(polar)], -1)
    parts.append((0.75 * normals, _quat_from_z_to(normals), np.tile([0.045, 0.045, 0.006], (n, 1)),
                  np.full(n, 0.85), _dc(np.tile([0.55, 0.55, 0.55], (n, 1)))))
    shell = (sum(p[0].shape[0] for p in parts[:-1]), n)

    # Axis marker at the upper left: 8 splats per needle along +x, +y, +z.
    origin = np.array([-2.1, -1.5, 0.0])
    t = (np.arange(8) + 0.5) / 8 * 0.6
    for axis, colour in ((0, [0.95, 0.1, 0.1]), (1, [0.1, 0.9, 0.1]), (2, [0.15, 0.3, 1.0])):
        means = np.tile(origin, (8, 1))
        means[:, axis] += t
        parts.append((means, np.tile([1.0, 0, 0, 0], (8, 1)), np.full((8, 3), 0.035),
                      np.full(8, 0.95), _dc(np.tile(colour, (8, 1)))))

    # An "F" glyph at the upper right (stem, top bar, middle bar), white.
    stem = np.stack([np.zeros(10), np.linspace(-0.5, 0.5, 10)], -1)
    top = np.stack([np.linspace(0.06, 0.4, 6), np.full(6, -0.5)], -1)
    mid = np.stack([np.linspace(0.06, 0.28, 4), np.full(4, 0.0)], -1)
    glyph = np.concatenate([stem, top, mid]) + [1.9, -1.3]
    means = np.concatenate([glyph, np.zeros((len(glyph), 1))], 1)
    parts.append((means, np.tile([1.0, 0, 0, 0], (len(glyph), 1)), np.full((len(glyph), 3), 0.045),
                  np.full(len(glyph), 0.95), _dc(np.tile([0.95, 0.95, 0.95], (len(glyph), 1)))))

    means = np.concatenate([p[0] for p in parts])
    quats = np.concatenate([p[1] for p in parts])
    scales = np.concatenate([p[2] for p in parts])
    opac = np.concatenate([p[3] for p in parts])
    sh = np.zeros((len(means), 16, 3))
    sh[:, 0] = np.concatenate([p[4] for p in parts])
    s0, sn = shell
    # Degree 1: Y_1,1 = -C1 x sits at k = 3; coefficient (-1, 0, +1) * 2.4 makes red rise with
    # +x and blue with -x.  Degree 2: (2zz - xx - yy) at k = 6 adds green looking along +z.
    # Degree 3: x (xx - 3yy) at k = 15 adds a faint three-lobed pattern around the y axis.
    sh[s0:s0 + sn, 3] = [-2.4, 0.0, 2.4]
    sh[s0:s0 + sn, 6] = [0.0, 0.35, 0.0]
    sh[s0:s0 + sn, 15] = [0.25, 0.25, 0.0]
    return Scene.from_activated(means, quats, scales, opac, sh)


def main() -> None:
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else HERE / "demo.ply"
    save_scene(out, build_demo())
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
