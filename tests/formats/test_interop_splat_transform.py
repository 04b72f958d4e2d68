"""Interoperability with splat-transform (PlayCanvas's independent implementation), pinned at
2.7.1 and 3.7.0 (tests/data/splat_transform_files.py), and with the official SPZ library it
ships (nianticlabs/spz as WebAssembly, @adobe/spz 0.2.2 in 2.7.1, 0.2.3 in 3.7.0; run by
tests/data/spz_library.mjs).  Every test runs once per version and skips with the reason when
that version (or node) is missing; all are marked ``npm``.

1. splatgl reads the .sog, .spz (v3 and v4), .glb and .compressed.ply files splat-transform
   wrote from the shared scenes (generated here when missing) to within the format's
   quantisation of the source scene.  SPZ: 2.7.1 writes the specification's RUB and 3.7.0
   PLY's RDF unconverted, with nothing in the file to tell them apart (:data:`WRITES`), so
   splatgl reads 3.7.0's files with ``--spz-axes rdf``; the other choice is the mirrored scene,
   and a small render shows it (PSNR).
2. splat-transform reads the .sog, .spz and .compressed.ply files splatgl writes (it reads no
   .glb) back to PLY, in the order splatgl wrote, within splatgl's own bounds of those writers.
   Its PLY holds an opacity logit of +Inf for an 8-bit alpha of 255, which splatgl rejects, so
   the sources' opacities are capped at 254/255 for this direction.  SPZ in every (version,
   axes) splatgl writes: 2.7.1 (the library, which honours the axes record) reads them all
   right; 3.7.0 reads stored bytes as RDF whatever the file says (:data:`READS_STORED`).
3. The official library: its CoordinateSystem values are splatgl's; it reads splatgl's SPZ and
   splatgl reads what it writes, with and without the axes record, converting or not.  Its
   0.2.3 build does not parse records after a gzip body (it logs "byteLength 4 exceeds
   remaining stream bytes" and assumes RUB), 0.2.2 does (:data:`LIBRARY_READS_GZIP_RECORDS`).

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

import json
import math
import subprocess
import zipfile
from pathlib import Path

import numpy as np
import pytest

from helpers import REPO, shared_file
from splat_transform_fixtures import exe, stfiles, version  # noqa: F401 (fixtures)
from splatgl.constants import SH_C0
from splatgl.formats.convert import ATTRIBUTES, conversion_error
from splatgl.formats import compressed_ply, load_scene, save_scene, spz_write, writer_for
from splatgl.formats import quantise as qz
from splatgl.formats import sog_write
from splatgl.measure.evaluation.metrics import psnr
from splatgl.api import default_camera
from splatgl.scene.splats import Scene

pytestmark = [pytest.mark.npm, pytest.mark.slow]

#: The axes each version writes SPZ in (versions 3 and 4 alike; no field in its files says).
WRITES = {"2.7.1": "rub", "3.7.0": "rdf"}
#: Whether each version reads an SPZ file's stored bytes as RDF whatever the file says (3.x:
#: a pure-JS reader, "decode is RAW"), instead of converting from the axes the file records
#: or, where it records none, from the specification's RUB (2.x: the official library).
READS_STORED = {"2.7.1": False, "3.7.0": True}
#: Whether the library bundled with each version parses extension records after a gzip body.
LIBRARY_READS_GZIP_RECORDS = {"2.7.1": True, "3.7.0": False}
#: The shared scene the SPZ axes and render checks use (64 splats, SH degree 3).
SMALL = "fixtures/test64_sh3.compressed.ply"


@pytest.fixture(scope="module")
def generated(version, exe, shared_scenes):
    for source in stfiles.SOURCES:
        shared_file(shared_scenes, source)
    out = stfiles.out_dir(version)
    try:
        stfiles.generate(out, shared_scenes, exe)
    except (RuntimeError, subprocess.TimeoutExpired) as exc:
        pytest.skip(f"splat-transform {version} could not write the test files: {exc}")
    return out


def capped(scene: Scene) -> Scene:
    """Opacity within 1/255..254/255: splat-transform's PLY holds +-Inf logits for 0 and 255."""
    cap = np.float32(math.log(254.0))  # logit(254/255)
    return Scene(scene.means, scene.quats, scene.log_scales,
                 np.clip(scene.opacity_logits, -cap, cap), scene.sh)


def flipped(scene: Scene, signs=(1.0, -1.0, -1.0)) -> np.ndarray:
    """The means of ``scene`` with its axes multiplied by ``signs`` (RDF <-> RUB)."""
    return scene.means.astype(np.float64) * np.asarray(signs)


def assert_means(got: np.ndarray, expected: np.ndarray, tol: float, what: str) -> None:
    err = float(np.abs(np.asarray(got, np.float64) - expected).max())
    assert err <= tol, f"{what}: positions off by {err:.3g} (> {tol:.3g})"


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
    mine = sog_write.error_bounds(source)
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
@pytest.mark.parametrize("suffix", [".sog", ".spz", ".v4.spz", ".glb", ".compressed.ply"])
def test_splatgl_reads_what_splat_transform_wrote(generated, shared_scenes, source_name, suffix):
    source = load_scene(shared_scenes / source_name)
    path = generated / (stfiles.stem(source_name) + suffix)
    axes = WRITES[generated.name] if suffix.endswith(".spz") else None
    got = load_scene(path, spz_axes=axes)
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
    elif suffix.endswith(".spz"):
        mine = writer_for(path).error_bounds(a, version=3)
        rest = None if not a.sh_degree else (
            8.0 / 128.0 + qz.clip_excess(a.sh[:, 1:], -1.0, 127.0 / 128.0) + 1e-6)
        bounds = {**mine, "sh_rest": rest}
    else:
        bounds = writer_for(path).error_bounds(a)
    check(a, b, bounds, f"{path.name} (splat-transform {generated.name}) against {source_name}")


@pytest.mark.parametrize("suffix", [".sog", ".spz", ".compressed.ply"])
def test_splat_transform_reads_what_splatgl_wrote(version, exe, shared_scenes, tmp_path, suffix):
    for name in stfiles.SOURCES:
        source = load_scene(shared_file(shared_scenes, name))
        if source.count > 8000:  # keep the run short: every k-th splat
            source = source.subset(np.arange(0, source.count, -(-source.count // 8000)))
        source = capped(source)
        ours = tmp_path / (stfiles.stem(name) + suffix)
        options = {"axes": WRITES[version]} if suffix == ".spz" else {}  # the axes it reads
        order = save_scene(ours, source, **options)
        expected = source if order is None else source.subset(order)
        back_path = tmp_path / (stfiles.stem(name) + suffix.replace(".", "_") + ".ply")
        try:
            stfiles.run(exe, ours, back_path)
        except (RuntimeError, subprocess.TimeoutExpired) as exc:
            pytest.fail(f"splat-transform could not read {ours.name}: {exc}")
        back = load_scene(back_path)
        a, b = paired(expected, back, False, tol=0.0)
        check(a, b, writer_for(ours).error_bounds(a),
              f"{ours.name} read by splat-transform {version}")


# SPZ axes, both directions, and the official library


def small_source(shared_scenes) -> Scene:
    return capped(load_scene(shared_file(shared_scenes, SMALL)))


def position_tol(scene: Scene) -> float:
    """Two SPZ quantisations of the positions (a file re-saved by the library)."""
    return 2.0 * spz_write.error_bounds(scene)["position"]


@pytest.mark.parametrize("suffix", [".spz", ".v4.spz"])
def test_spz_axes_of_each_version_and_the_render(version, generated, shared_scenes, gl_renderer,
                                                 suffix):
    """Read with the axes the version writes, the donut renders as its source; with the other
    choice (the default for 3.7.0's files: RUB, as the specification says) it is mirrored."""
    donut = stfiles.SOURCES[0]
    source = load_scene(shared_file(shared_scenes, donut))
    path = generated / (stfiles.stem(donut) + suffix)
    right = WRITES[version]
    wrong = "rdf" if right == "rub" else "rub"
    tol = position_tol(source)
    assert_means(load_scene(path, spz_axes=right).means, flipped(source, (1, 1, 1)), tol, right)
    mirrored = load_scene(path, spz_axes=wrong)
    assert_means(mirrored.means, flipped(source), tol, wrong)
    camera = default_camera(source, 96, 64)
    image = lambda scene: gl_renderer.render(scene, camera)[..., :3]  # noqa: E731
    expected = image(source)
    assert psnr(image(load_scene(path, spz_axes=right)), expected) > 40.0
    assert psnr(image(mirrored), expected) < 25.0


@pytest.mark.parametrize("spz_version,axes", [(3, None), (3, "rub"), (3, "rdf"),
                                              (2, None), (2, "rub"), (2, "rdf")])
def test_splat_transform_reads_splatgl_spz_axes(version, exe, shared_scenes, tmp_path,
                                                spz_version, axes):
    source = small_source(shared_scenes)
    ours = tmp_path / "ours.spz"
    save_scene(ours, source, version=spz_version, axes=axes)
    stored = spz_write.stored_axes(spz_version, axes)
    back = tmp_path / "back.ply"
    stfiles.run(exe, ours, back)
    same = not READS_STORED[version] or stored == "RDF"
    expected = flipped(source, (1, 1, 1) if same else (1, -1, -1))
    assert_means(load_scene(back).means, expected, position_tol(source),
                 f"splat-transform {version} reading splatgl's v{spz_version} {stored}")


def library(version: str, *args: str) -> str:
    proc = subprocess.run(["node", str(REPO / "tests" / "data" / "spz_library.mjs"),
                           str(stfiles.library(version)), *map(str, args)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-500:]
    return proc.stdout


def test_library_coordinate_systems_are_splatgl_s(version):
    from splatgl.formats.spz_axes import COORDINATE_SYSTEMS
    assert json.loads(library(version, "enum")) == {n: i for i, n in enumerate(COORDINATE_SYSTEMS)}


@pytest.mark.parametrize("spz_version,axes", [(3, None), (3, "rdf"), (2, None), (2, "rub")])
def test_library_reads_splatgl_spz(version, shared_scenes, tmp_path, spz_version, axes):
    source = small_source(shared_scenes)
    ours = tmp_path / "ours.spz"
    save_scene(ours, source, version=spz_version, axes=axes)
    stored = spz_write.stored_axes(spz_version, axes)
    recorded = (spz_version, stored) != (3, "RUB")
    got = json.loads(library(version, "load", ours, "RDF"))
    assert bool(got["extensions"]) == (recorded and LIBRARY_READS_GZIP_RECORDS[version])
    same = stored == "RUB" or LIBRARY_READS_GZIP_RECORDS[version]  # else read as RUB
    expected = flipped(source, (1, 1, 1) if same else (1, -1, -1))
    assert_means(np.reshape(got["positions"], (-1, 3)), expected, position_tol(source),
                 f"library of {version} reading splatgl's v{spz_version} {stored}")


@pytest.mark.parametrize("case", ["spec v3", "spec v4", "unconverted v4", "recorded v4"])
def test_splatgl_reads_library_spz(version, shared_scenes, tmp_path, case):
    """The library re-saves splatgl's file: converting to RUB (the specification), storing RDF
    unconverted (``from: UNSPECIFIED``, as splat-transform 3.x and its own ply_to_spz do), or
    keeping an RDF axes record it read (version 4: records in the header zone)."""
    source = small_source(shared_scenes)
    ours, theirs = tmp_path / "ours.spz", tmp_path / "theirs.spz"
    save_scene(ours, source, axes="rdf" if case == "recorded v4" else None)
    to, frm = ("RDF", "UNSPECIFIED") if case == "unconverted v4" else ("RDF", "RDF")
    library(version, "save", ours, theirs, to, frm, case[-1])
    tol = position_tol(source)
    got = load_scene(theirs)
    if case == "unconverted v4":  # nothing says RDF: read as the specification's RUB ...
        assert_means(got.means, flipped(source), tol, case)
        got = load_scene(theirs, spz_axes="rdf")  # ... or as told
    elif case == "recorded v4" and not LIBRARY_READS_GZIP_RECORDS[version]:
        assert_means(got.means, flipped(source), tol, f"{case}: the record was lost on loading")
        return
    assert_means(got.means, flipped(source, (1, 1, 1)), tol, case)
    e = conversion_error(source, got)
    assert e["rotation"]["max"] <= 2 * spz_write.error_bounds(source)["rotation"]
    assert e["sh_rest"]["max"] <= 2 * spz_write.error_bounds(source)["sh_rest"]
