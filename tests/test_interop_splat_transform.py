"""Interoperability with splat-transform (PlayCanvas's independent implementation).

1. splatgl reads the .sog, .spz (v3), .glb and .compressed.ply files splat-transform wrote from
   the shared scenes (tests/data/splat_transform_files.py; generated here when missing) to
   within the format's quantisation of the source scene.
2. splat-transform reads the .sog, .spz and .compressed.ply files splatgl writes (it reads no
   .glb) back to PLY, in the order splatgl wrote, within splatgl's own bounds of those writers.
   Its PLY holds an opacity logit of +Inf for an 8-bit alpha of 255, which splatgl rejects, so
   the sources' opacities are capped at 254/255 for this direction.

Rows: splat-transform keeps the order in SPZ and GLB and sorts SOG and compressed PLY along its
own Morton curve, so those rows are matched to the source by nearest position (accepting only
one-to-one matches, at least 99.9% of the rows).

Bounds for files splat-transform wrote (its encoders differ from splatgl's in rounding):
- SOG: means, quaternions and opacity are truncated, not rounded: one full step (twice
  splatgl's half-step bounds); scale and colour within half the largest gap of the file's own
  codebooks (meta.json), as splatgl's codebook bound computes.  Splats whose opacity truncates
  to alpha 0 (opacity < 1/255, which every renderer skips) lose their colour: splat-transform's
  lossless WebP encoder does not keep the RGB of transparent texels (1518 of the donut's 45,624
  read back as colour index 0), so colour is checked on the splats with alpha > 0 only.
- SPZ: written by Niantic's library, which keeps 5 bits of degree-1 SH and 4 bits of higher
  degrees (buckets of 8 and 16 of 128 per unit): SH error <= 8/128; other attributes as
  splatgl's SPZ v3 bounds.
- compressed PLY: the same arithmetic as splatgl's writer, but on splat-transform's chunks: the
  bounds are computed from the file's own chunk table.
- GLB: float32 values with the same axis turn: splatgl's glTF bounds.

Skips with the reason when node / splat-transform is not installed (see the script).
"""

from __future__ import annotations

import importlib.util
import json
import math
import subprocess
import zipfile
from pathlib import Path

import numpy as np
import pytest

from helpers import REPO, shared_file
from splatgl.constants import SH_C0
from splatgl.convert import ATTRIBUTES, conversion_error
from splatgl.formats import compressed_ply, load_scene, save_scene, writer_for
from splatgl.formats import quantise as qz
from splatgl.formats import sog as sog_format
from splatgl.scene import Scene

pytestmark = [pytest.mark.npm, pytest.mark.slow]

_spec = importlib.util.spec_from_file_location(
    "splat_transform_files", REPO / "tests" / "data" / "splat_transform_files.py")
stfiles = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(stfiles)


@pytest.fixture(scope="module")
def exe():
    path = stfiles.executable()
    if path is None:
        pytest.skip("splat-transform not installed (npm install --prefix .npm-tools "
                    "@playcanvas/splat-transform)")
    return path


@pytest.fixture(scope="module")
def generated(exe, shared_scenes):
    for source in stfiles.SOURCES:
        shared_file(shared_scenes, source)
    try:
        stfiles.generate(stfiles.DEFAULT_OUT, shared_scenes, exe)
    except (RuntimeError, subprocess.TimeoutExpired) as exc:
        pytest.skip(f"splat-transform could not write the test files: {exc}")
    return stfiles.DEFAULT_OUT


def match_rows(a: np.ndarray, b: np.ndarray, tol: float) -> np.ndarray:
    """(N,) index of the row of ``a`` (M, 3) nearest each row of ``b`` (N, 3) among rows with
    ``|dx| <= tol``; -1 where none or where two rows of ``b`` chose the same row of ``a``."""
    order = np.argsort(a[:, 0], kind="stable")
    ax = a[order, 0]
    lo = np.searchsorted(ax, b[:, 0] - tol)
    hi = np.searchsorted(ax, b[:, 0] + tol, "right")
    best = np.full(len(b), -1)
    best_d = np.full(len(b), np.inf)
    for k in range(int((hi - lo).max(initial=0))):
        idx = lo + k
        cand = order[np.minimum(idx, len(a) - 1)]
        d = np.linalg.norm(a[cand] - b, axis=1)
        better = (idx < hi) & (d < best_d)
        best[better], best_d[better] = cand[better], d[better]
    taken, counts = np.unique(best[best >= 0], return_counts=True)
    best[np.isin(best, taken[counts > 1])] = -1
    return best


def paired(source, got, reordered: bool, tol: float):
    """(source rows, got rows) paired one to one (see the module notes)."""
    if not reordered:
        assert got.count == source.count
        return source, got
    perm = match_rows(source.means.astype(np.float64), got.means.astype(np.float64), tol)
    ok = perm >= 0
    assert ok.mean() >= 0.999, f"only {ok.mean():.4f} of the rows matched one to one"
    return source.subset(perm[ok]), got.subset(np.flatnonzero(ok))


def sog_bounds(source, path: Path) -> dict:
    mine = sog_format.error_bounds(source)
    with zipfile.ZipFile(path) as zf:
        meta = json.loads(zf.read("meta.json"))
    scale_book = np.float32(meta["scales"]["codebook"])
    dc_book = np.float32(meta["sh0"]["codebook"])
    return {**mine, "position": 2 * mine["position"], "opacity": 1 / 255 + 1e-6,
            "rotation": qz.half_step_rotation_deg(2.0 / (255.0 * math.sqrt(2.0))),
            "scale": qz.relative_scale(qz.codebook_bound(scale_book, source.log_scales)) + 1e-6,
            "color": SH_C0 * qz.codebook_bound(dc_book, source.sh[:, 0]) + 1e-6}


def cply_bounds(source, path: Path) -> dict:
    """Bounds from the file's own chunks: half a step of each chunk's range (as splatgl's)."""
    mine = writer_for(path).error_bounds(source)
    chunks = compressed_ply._read_elements(path, path.read_bytes())["chunk"]
    steps = np.array([(1 << b) - 1 for b in qz.CPLY_XYZ_BITS], np.float64)

    def half(names):
        lo = np.stack([chunks["min_" + n] for n in names], 1).astype(np.float64)
        hi = np.stack([chunks["max_" + n] for n in names], 1).astype(np.float64)
        return (hi - lo) / 2.0

    pos = np.sqrt(((half("xyz") / steps) ** 2).sum(axis=1)).max()
    log = (half(["scale_x", "scale_y", "scale_z"]) / steps).max()
    colour = (half("rgb") / 255.0).max()
    return {**mine, "position": pos * (1 + 1e-6) + qz.position_slack(source.means),
            "scale": qz.relative_scale(log) * (1 + 1e-6) + 1e-6, "color": colour + 1e-6}


def check(source, got, bounds: dict, what: str) -> None:
    e = conversion_error(source, got)
    for attr in ATTRIBUTES:
        if e[attr] is None or bounds.get(attr) is None:
            continue
        assert e[attr]["max"] <= bounds[attr], (
            f"{what}: {attr} error {e[attr]['max']:.6g} > bound {bounds[attr]:.6g}")


@pytest.mark.parametrize("source_name", stfiles.SOURCES)
@pytest.mark.parametrize("suffix", [".sog", ".spz", ".glb", ".compressed.ply"])
def test_splatgl_reads_what_splat_transform_wrote(generated, shared_scenes, source_name, suffix):
    source = load_scene(shared_scenes / source_name)
    path = generated / (stfiles.stem(source_name) + suffix)
    got = load_scene(path)
    reordered = suffix in (".sog", ".compressed.ply")
    a, b = paired(source, got, reordered, tol=1e-3 * max(1.0, source.robust_radius))
    if suffix == ".sog":
        bounds = sog_bounds(a, path)
        visible = b.opacities > 0.5 / 255.0
        check(a.subset(visible), b.subset(visible), {"color": bounds.pop("color")},
              f"{path.name} (splat-transform), splats with alpha > 0")
        if a.sh_degree:  # the palette: no a-priori bound; better than dropping the SH
            e = conversion_error(a, b)["sh_rest"]
            assert e["mean"] < np.abs(a.sh[:, 1:]).mean()
    elif suffix == ".compressed.ply":
        bounds = cply_bounds(a, path)
    elif suffix == ".spz":
        mine = writer_for(path).error_bounds(a, version=3)
        rest = None if not a.sh_degree else (
            8.0 / 128.0 + qz.clip_excess(a.sh[:, 1:], -1.0, 127.0 / 128.0) + 1e-6)
        bounds = {**mine, "sh_rest": rest}
    else:
        bounds = writer_for(path).error_bounds(a)
    check(a, b, bounds, f"{path.name} (splat-transform) against {source_name}")


@pytest.mark.parametrize("suffix", [".sog", ".spz", ".compressed.ply"])
def test_splat_transform_reads_what_splatgl_wrote(exe, shared_scenes, tmp_path, suffix):
    for name in stfiles.SOURCES:
        source = load_scene(shared_file(shared_scenes, name))
        if source.count > 8000:  # keep the run short: every k-th splat
            source = source.subset(np.arange(0, source.count, -(-source.count // 8000)))
        cap = np.float32(math.log(254.0))  # logit(254/255)
        source = Scene(source.means, source.quats, source.log_scales,
                       np.minimum(source.opacity_logits, cap), source.sh)
        ours = tmp_path / (stfiles.stem(name) + suffix)
        order = save_scene(ours, source)
        expected = source if order is None else source.subset(order)
        back_path = tmp_path / (stfiles.stem(name) + suffix.replace(".", "_") + ".ply")
        try:
            stfiles.run(exe, ours, back_path)
        except (RuntimeError, subprocess.TimeoutExpired) as exc:
            pytest.fail(f"splat-transform could not read {ours.name}: {exc}")
        back = load_scene(back_path)
        a, b = paired(expected, back, False, tol=0.0)
        check(a, b, writer_for(ours).error_bounds(a), f"{ours.name} read by splat-transform")
