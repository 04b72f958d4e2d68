"""The bundled demo scene is what scenes/make_demo.py builds, and it shows what it promises."""

from __future__ import annotations

import subprocess
import sys

import numpy as np

from helpers import REPO
from splatgl.formats import load_scene
from splatgl.splatmath.project import sh_color


def test_committed_demo_is_regenerated_byte_for_byte(tmp_path):
    out = tmp_path / "demo.ply"
    subprocess.run([sys.executable, str(REPO / "scenes" / "make_demo.py"), str(out)], check=True,
                   capture_output=True)
    assert out.read_bytes() == (REPO / "scenes" / "demo.ply").read_bytes()


def test_demo_has_anisotropic_splats_at_many_orientations_and_view_dependent_sh():
    scene = load_scene(REPO / "scenes" / "demo.ply")
    assert scene.sh_degree == 3
    s = scene.scales
    aniso = s.max(1) / s.min(1)
    assert (aniso > 5).sum() >= 50  # petals, needles and flattened shell splats
    # major-axis directions of the elongated splats cover many angles in the image plane
    from splatgl.splatmath.project import quat_to_rotmat

    rot = quat_to_rotmat(scene.rotations[aniso > 5].astype(np.float64))
    major = rot[np.arange(len(rot)), :, s[aniso > 5].argmax(1)]
    angles = np.degrees(np.arctan2(major[:, 1], major[:, 0])) % 180
    assert len(np.unique(np.round(angles / 15))) >= 8
    # the shell's colour differs between looking towards +x and towards -x
    sh = scene.sh.astype(np.float64)
    right = sh_color(sh, np.tile([1.0, 0, 0], (scene.count, 1)))
    left = sh_color(sh, np.tile([-1.0, 0, 0], (scene.count, 1)))
    changed = np.abs(right - left).max(1)
    assert (changed > 0.5).sum() > 1000
    assert np.all(right[changed > 0.5, 0] > left[changed > 0.5, 0])  # red towards +x
