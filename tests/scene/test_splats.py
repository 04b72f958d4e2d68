"""The Scene object itself: how it prints, and what the API's scene check lets through."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

import splatgl
from helpers import random_scene
from splatgl.commands._common import demo_scene_path
from splatgl.scene.splats import SplatKind, require_scene


def test_a_scene_prints_as_one_short_line():
    """print(scene) dumped every array of the dataclass (thousands of lines for a real scene)."""
    loaded = splatgl.load_scene(demo_scene_path())
    assert repr(loaded) == str(loaded) == "Scene(1,604 splats, 3dgs, SH degree 3, source 'demo.ply')"
    assert repr(random_scene(90854, degree=0)) == "Scene(90,854 splats, 3dgs, SH degree 0)"
    surfels = random_scene(12, degree=1, kind=SplatKind.SURFEL_2D)
    assert repr(surfels.subset(slice(0, 5))) == "Scene(5 splats, 2dgs, SH degree 1)"


def test_default_camera_takes_a_framing_proxy_but_the_renderers_want_a_scene():
    """A streamed scene frames its views through a proxy holding what the framing reads
    (splatgl.lod.stream_frames.framing_scene); nothing else passes for a scene."""
    scene = random_scene(50)
    proxy = SimpleNamespace(robust_bounds=scene.robust_bounds, robust_radius=scene.robust_radius,
                            source=None)
    reads = ("robust_bounds", "robust_radius", "source")
    assert require_scene(proxy, "default_camera", reads) is proxy
    framed, plain = splatgl.default_camera(proxy, 32, 24), splatgl.default_camera(scene, 32, 24)
    np.testing.assert_array_equal(framed.world_to_camera, plain.world_to_camera)
    with pytest.raises(TypeError, match=r"^render: scene must be a splatgl Scene .*, got "
                                        r"SimpleNamespace namespace\(robust_bounds=.*\.\.\.$"):
        require_scene(proxy, "render")
    with pytest.raises(TypeError, match=r"^default_camera: .*got PosixPath\('x.ply'\)$"):
        splatgl.default_camera(Path("x.ply"))
