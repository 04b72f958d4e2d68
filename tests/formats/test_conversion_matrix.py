"""Conversion matrix: every shared real scene, read, written in every writable format, read back;
each attribute's error inside the bound the writer states for that scene.

Sources are the real files of every readable format in the shared scenes (PLY, compressed PLY,
SPZ v2/v3/v4, .splat, .ksplat) plus SOG and GLB files written by splatgl from the donut (the
readable formats no shared file holds; files written by splat-transform are covered by
test_interop_splat_transform.py).  To keep the module at a few seconds the big scenes are
subsampled to every k-th splat (at most MAX_SPLATS); subsampling changes no value, only which
splats take part.  Bounds come from each writer's ``error_bounds`` (see
splatgl/formats/quantise.py for their derivations); SOG's SH palette (k-means) has no a-priori
bound and is checked against the spread of the coefficients instead.
"""

from __future__ import annotations

import numpy as np
import pytest

from helpers import shared_file
from test_convert import REAL_FILES
from splatgl.formats.convert import ATTRIBUTES, conversion_error, error_bounds
from splatgl.formats import load_scene, save_scene, writer_for

#: Largest subsample of a real scene used here.
MAX_SPLATS = 6000

SOURCES = REAL_FILES + ["written:sog", "written:glb"]

#: (output name, writer options)
TARGETS = [
    ("out.ply", {}), ("out.compressed.ply", {}), ("out2.spz", {"version": 2}),
    ("out3.spz", {"version": 3}), ("out.sog", {}), ("meta.json", {}), ("out.glb", {}),
    ("out.gltf", {}), ("out.splat", {}),
]


def subsample(scene):
    step = max(1, -(-scene.count // MAX_SPLATS))
    return scene if step == 1 else scene.subset(np.arange(0, scene.count, step))


@pytest.fixture(scope="module")
def sources(shared_scenes, tmp_path_factory):
    """name -> subsampled scene, read from the real file (or from a file splatgl wrote)."""
    out = {}
    tmp = tmp_path_factory.mktemp("matrix_sources")
    for name in SOURCES:
        if name.startswith("written:"):
            donut = subsample(load_scene(shared_file(shared_scenes, "ply/donut_sh0.ply")))
            path = tmp / f"donut.{name.split(':')[1]}"
            save_scene(path, donut)
            out[name] = load_scene(path)
        else:
            out[name] = subsample(load_scene(shared_file(shared_scenes, name)))
    return out


@pytest.mark.parametrize("source", SOURCES)
def test_every_writer_round_trips_within_its_bounds(sources, source, tmp_path):
    scene = sources[source]
    for target, options in TARGETS:
        folder = tmp_path / target.replace(".", "_")
        folder.mkdir()
        path = folder / target
        writer = writer_for(path)
        written = scene.with_sh_degree(0) if writer.NAME == "splat" else scene
        order = save_scene(path, written, **options)
        back = load_scene(path)
        expected = written if order is None else written.subset(order)
        e = conversion_error(expected, back)
        bounds = error_bounds(writer, written, **options)
        if bounds is None:  # lossless
            assert e["bit_exact"], f"{source} -> {target}"
            continue
        for attr in ATTRIBUTES:
            if e[attr] is None:
                continue
            if bounds[attr] is None:  # SOG's SH palette: better than no SH at all
                spread = np.abs(expected.sh[:, 1:]).mean()
                assert e[attr]["mean"] <= spread, f"{source} -> {target}: {attr}"
                continue
            assert e[attr]["max"] <= bounds[attr], (
                f"{source} -> {target}: {attr} error {e[attr]['max']:.6g} > bound "
                f"{bounds[attr]:.6g}")

