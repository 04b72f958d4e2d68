"""Compressed PLY, SPZ and ksplat loaders against the real files in the shared scenes.

Cross-checks use independent decoders written here (a float-only PLY reader, a .splat reader)
so the loaders are compared with their sources, not with themselves.  Tolerances are the
formats' quantisation steps, named where used.
"""

from __future__ import annotations

import gzip
import struct
from pathlib import Path

import numpy as np
import pytest

from splatgl.constants import SH_C0
from splatgl.errors import SceneFormatError
from splatgl.formats import compressed_ply, detect_format, ksplat, load_scene, spz, spz_axes

# --- independent reference decoders -----------------------------------------------------------


def read_float_ply(path: Path) -> dict[str, np.ndarray]:
    """Columns of a binary little-endian PLY whose only element is an all-float vertex."""
    raw = path.read_bytes()
    end = raw.index(b"end_header\n") + len(b"end_header\n")
    names = [line.split()[2] for line in raw[:end].decode().splitlines()
             if line.startswith("property float")]
    table = np.frombuffer(raw, "<f4", offset=end).reshape(-1, len(names))
    return {name: table[:, i].astype(np.float64) for i, name in enumerate(names)}


def read_splat_rows(path: Path) -> dict[str, np.ndarray]:
    """antimatter15 .splat: position f32x3, linear scale f32x3, RGBA u8, rotation u8 (w,x,y,z)."""
    rows = np.frombuffer(path.read_bytes(), np.dtype([("p", "<f4", 3), ("s", "<f4", 3),
                                                      ("c", "u1", 4), ("q", "u1", 4)]))
    return {"means": rows["p"].astype(np.float64), "log_scales": np.log(rows["s"]),
            "rgb": rows["c"][:, :3] / 255.0, "alpha": rows["c"][:, 3] / 255.0,
            "quats": (rows["q"] - 128.0) / 128.0}


def covariances(scene) -> np.ndarray:
    """(N, 3, 3) float64 R S S R^T, to compare rotations whatever their sign or symmetry."""
    w, x, y, z = scene.rotations.astype(np.float64).T
    r = np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], axis=1)
    m = r * scene.scales.astype(np.float64)[:, None, :]
    return m @ m.transpose(0, 2, 1)


def sigmoid(x) -> np.ndarray:
    return 1.0 / (1.0 + np.exp(-np.asarray(x, np.float64)))


def assert_sane(scene) -> None:
    """Unit-ish quaternions, finite values, colours and scales in plausible ranges."""
    norms = np.linalg.norm(scene.quats.astype(np.float64), axis=1)
    assert np.abs(norms - 1).max() < 2e-3
    assert 1e-3 < scene.robust_radius < 1e3
    rgb = 0.5 + SH_C0 * scene.sh[:, 0]
    lo, hi = np.percentile(rgb, [1, 99])
    assert -0.5 < lo and hi < 2.0
    assert np.all((scene.log_scales > -30) & (scene.log_scales < 5))


# --- compressed PLY ---------------------------------------------------------------------------

COMPRESSED = [("compressed_ply/biker.compressed.ply", 152_746, 0),
              ("compressed_ply/guitar.compressed.ply", 90_854, 0),
              ("fixtures/test64_sh3.compressed.ply", 64, 3)]


@pytest.mark.parametrize("name,count,degree", COMPRESSED)
def test_compressed_ply_loads(shared_scenes, name, count, degree):
    path = shared_scenes / name
    assert detect_format(path) is compressed_ply
    scene = load_scene(path)
    assert (scene.count, scene.sh_degree) == (count, degree)
    assert_sane(scene)


def test_compressed_ply_sh_small_and_centred(shared_scenes):
    """uchar f_rest -> (b + 0.5) / 32 - 4: higher-order SH of a trained scene sit near 0."""
    rest = compressed_ply.read(shared_scenes / "fixtures/test64_sh3.compressed.ply").sh[:, 1:]
    assert abs(float(rest.mean())) < 0.05
    assert float(np.median(np.abs(rest))) < 0.2
    assert np.abs(rest).max() <= 4.0


def test_compressed_ply_matches_spz_of_the_same_scene(shared_scenes):
    """biker.compressed.ply and biker_v4.spz are one scene: rotation order (w, x, y, z), colour
    bounds, alpha and the SPZ v4 axis flip all have to be right for these to agree."""
    a = compressed_ply.read(shared_scenes / "compressed_ply/biker.compressed.ply")
    b = spz.read(shared_scenes / "spz/biker_v4.spz")
    assert np.abs(a.means - b.means).max() < 2.0 ** -12 + 1e-4  # SPZ 12-bit step + 11-bit chunk
    dots = np.abs((a.rotations.astype(np.float64) * b.rotations).sum(axis=1))
    assert dots.min() > 0.999
    rgb_a, rgb_b = SH_C0 * a.sh[:, 0], SH_C0 * b.sh[:, 0]
    assert np.abs(rgb_a - rgb_b).max() < 0.5 / 255 / spz.COLOR_SCALE * SH_C0 + 1e-3
    assert np.abs(a.opacities - b.opacities).max() < 1e-6  # the same 8-bit alpha
    assert np.percentile(np.abs(a.log_scales - b.log_scales), 99) < 1 / 32 + 1e-3


def test_compressed_ply_missing_property_is_named(tmp_path, shared_scenes):
    data = (shared_scenes / "fixtures/test64_sh3.compressed.ply").read_bytes()
    bad = tmp_path / "bad.compressed.ply"
    bad.write_bytes(data.replace(b"property float max_scale_y", b"property float max_scale_q"))
    with pytest.raises(SceneFormatError, match="max_scale_y"):
        compressed_ply.read(bad)


def test_compressed_ply_huge_vertex_count_fails_before_allocating(tmp_path, shared_scenes):
    data = (shared_scenes / "fixtures/test64_sh3.compressed.ply").read_bytes()
    bad = tmp_path / "huge.compressed.ply"
    bad.write_bytes(data.replace(b"element vertex 64\n", b"element vertex 4000000000\n"))
    with pytest.raises(SceneFormatError, match="truncated"):
        compressed_ply.read(bad)


# --- SPZ --------------------------------------------------------------------------------------


def test_spz_v2_matches_its_source_ply(shared_scenes):
    """donut_sh0_v2.spz was written from donut_sh0.ply: positions agree to the fixed-point step,
    colours with scale 0.15, log-scales to 1/16, alpha to 1/255, with no axis flip."""
    ply = read_float_ply(shared_scenes / "ply/donut_sh0.ply")
    scene = spz.read(shared_scenes / "spz/donut_sh0_v2.spz")
    assert (scene.count, scene.sh_degree) == (45_624, 0)
    means = np.stack([ply["x"], ply["y"], ply["z"]], 1)
    assert np.abs(scene.means - means).max() <= 2.0 ** -13 + 1e-6  # half of 12 fractional bits
    dc = np.stack([ply[f"f_dc_{i}"] for i in range(3)], 1)
    inside = np.all(np.abs(dc * spz.COLOR_SCALE) < 0.49, axis=1)  # not clipped at 0 or 255
    assert np.abs(scene.sh[inside, 0] - dc[inside]).max() <= 0.5 / 255 / spz.COLOR_SCALE + 1e-5
    assert np.abs(scene.opacities - sigmoid(ply["opacity"])).max() <= 0.5 / 255 + 1e-6
    scales = np.stack([ply[f"scale_{i}"] for i in range(3)], 1)
    assert np.abs(scene.log_scales - scales).max() <= 1 / 32 + 1e-5
    q = np.stack([ply[f"rot_{i}"] for i in range(4)], 1)
    q = q / np.linalg.norm(q, axis=1, keepdims=True) * np.sign(q[:, :1])
    # 8-bit x, y, z with w derived: worst where w is near 0, so compare by angle.
    dots = np.abs((scene.rotations * q).sum(axis=1))
    assert dots.min() > 0.995
    assert np.median(np.abs(scene.rotations - q)) < 0.005


MINIMAL_SPZ = ["minimal-v2.spz", "minimal-v3.spz", "minimal-v4.spz", "minimal-raw.spz"]


@pytest.mark.parametrize("name", MINIMAL_SPZ)
def test_minimal_spz_variants_match_minimal_splat(shared_scenes, name):
    """All four variants are minimal.splat (v3/v4 stored RUB: flipped back by default)."""
    ref = read_splat_rows(shared_scenes / "fixtures/minimal.splat")
    path = shared_scenes / "fixtures" / name
    assert detect_format(path) is spz
    scene = spz.read(path)
    assert scene.count == 4 and scene.sh_degree == 0
    step = 2.0 ** -8  # coarsest fixed point among the variants (v2: 8 fractional bits)
    assert np.abs(scene.means - ref["means"]).max() <= step
    assert np.abs(scene.log_scales - ref["log_scales"]).max() <= 1 / 32
    assert np.abs(scene.opacities - ref["alpha"]).max() <= 1 / 255
    cov = covariances(scene)
    assert np.allclose(cov, cov[:, :1, :1] * np.eye(3), atol=1e-4)  # isotropic, like the source
    colour = 0.5 + spz.COLOR_SCALE * scene.sh[:, 0].astype(np.float64)
    if name in ("minimal-v2.spz", "minimal-raw.spz"):
        # These two fixtures hold the .splat colour bytes unchanged (their writer skipped the
        # 0.15 colour scale), so only the stored byte, not f_dc, matches the source.
        assert np.abs(colour - ref["rgb"]).max() < 1e-6
    else:
        dc = (ref["rgb"] - 0.5) / SH_C0
        assert np.abs(scene.sh[:, 0] - dc).max() <= 0.5 / 255 / spz.COLOR_SCALE + 1e-5


def test_spz_biker_v4_loads(shared_scenes):
    scene = spz.read(shared_scenes / "spz/biker_v4.spz")
    assert (scene.count, scene.sh_degree) == (152_746, 0)
    assert_sane(scene)


def _spz_body(version: int, count: int, sh_degree: int, rng) -> tuple[bytes, dict]:
    """A raw SPZ body with random attribute bytes, and those bytes by attribute."""
    header = spz.Header(version, count, sh_degree, 10, 0, 0)
    arrays = {name: rng.integers(0, 256, (count, b), dtype=np.uint8)
              for name, b in header.attribute_bytes()}
    head = struct.pack(spz.HEADER_FORMAT, spz.MAGIC, version, count, sh_degree, 10, 0, 0)
    return head + b"".join(a.tobytes() for a in arrays.values()), arrays


@pytest.mark.parametrize("version", [2, 3])
def test_spz_sh_layout_is_coefficient_major_rgb_interleaved(tmp_path, version):
    rng = np.random.default_rng(version)
    body, arrays = _spz_body(version, 5, 2, rng)
    path = tmp_path / "sh.spz"
    path.write_bytes(gzip.compress(body))
    scene = spz.read_spz(path, axes="rdf")
    want = (arrays["sh"].astype(np.float64) - 128) / 128
    assert scene.sh.shape == (5, 9, 3)
    assert np.allclose(scene.sh[:, 1:].reshape(5, 24), want)
    flipped = spz.read_spz(path, axes="rub")
    signs = spz_axes.sh_signs(np.array([1, -1, -1]), 8)
    assert np.allclose(flipped.sh[:, 1:], scene.sh[:, 1:] * signs[:, None])
    assert np.allclose(flipped.means, scene.means * [1, -1, -1])


@pytest.mark.parametrize("version", [0, 5, 7])
def test_spz_unsupported_version_is_named(tmp_path, version):
    body, _ = _spz_body(2, 3, 0, np.random.default_rng(0))
    body = body[:4] + struct.pack("<I", version) + body[8:]
    for name, data in (("raw.spz", body), ("gz.spz", gzip.compress(body))):
        path = tmp_path / name
        path.write_bytes(data)
        with pytest.raises(SceneFormatError, match=f"SPZ version {version} is not supported"):
            spz.read(path)


def test_spz_truncated_and_huge_count(tmp_path):
    body, _ = _spz_body(2, 10, 0, np.random.default_rng(1))
    path = tmp_path / "t.spz"
    path.write_bytes(body[:-7])
    with pytest.raises(SceneFormatError, match=r"needs 10 x 19 = 190 bytes, but only 183"):
        spz.read(path)
    path.write_bytes(gzip.compress(body[:8] + struct.pack("<I", 0xFFFFFFFF) + body[12:]))
    with pytest.raises(SceneFormatError, match="truncated"):
        spz.read(path)


# --- ksplat -----------------------------------------------------------------------------------


def test_minimal_ksplat_matches_minimal_splat(shared_scenes):
    """Level 0 with sectionCount = maxSplatCount = 0 in the main header still loads all 4."""
    path = shared_scenes / "fixtures/minimal.ksplat"
    assert detect_format(path) is ksplat
    scene = load_scene(path)
    ref = read_splat_rows(shared_scenes / "fixtures/minimal.splat")
    assert (scene.count, scene.sh_degree) == (4, 0)
    assert np.allclose(scene.means, ref["means"])
    assert np.allclose(scene.log_scales, ref["log_scales"])
    assert np.allclose(scene.opacities, ref["alpha"], atol=1e-6)
    assert np.allclose(scene.sh[:, 0], (ref["rgb"] - 0.5) / SH_C0, atol=1e-6)
    assert np.allclose(covariances(scene), np.eye(3) * 0.01, atol=1e-6)


def write_ksplat(path: Path, level: int, means, scales, quats, rgba, sh_rest, bucket_size=3,
                 block=4.0) -> None:
    """A one-section ksplat as this module reads it (full buckets, then one partial bucket).

    Only a self-consistency check for levels 1-2: no real file of those levels is at hand.
    """
    n = means.shape[0]
    degree = {0: 0, 9: 1, 24: 2, 45: 3}[sh_rest.shape[1]]
    full, tail = divmod(n, bucket_size)
    buckets = full + (1 if tail else 0)
    bucket = np.arange(n) // bucket_size
    centres = np.stack([means[bucket == b].mean(0) for b in range(buckets)])
    rng_ = 32767
    header = bytearray(ksplat.HEADER_BYTES)
    struct.pack_into("<2B2x4I2H5f", header, 0, 0, 1, 1, 1, n, n, level, 0, 0, 0, 0, -2, 2)
    sec = bytearray(ksplat.SECTION_HEADER_BYTES)
    struct.pack_into("<4If2H4IH", sec, 0, n, n, bucket_size, buckets, block, 12, 0, rng_, 0,
                     full, 1 if tail else 0, degree)
    rec = np.zeros(n, ksplat.record_dtype(level, degree))
    if level == 0:
        rec["centre"] = means
    else:
        rec["centre"] = np.rint((means - centres[bucket]) / (block / 2 / rng_) + rng_)
    rec["scale"], rec["rotation"], rec["rgba"] = scales, quats, rgba
    if degree:
        rec["sh"] = np.rint((sh_rest + 2) / 4 * 255) if level == 2 else sh_rest
    meta = np.array([tail] if tail else [], "<u4").tobytes()
    path.write_bytes(bytes(header) + bytes(sec) + meta + centres.astype("<f4").tobytes()
                     + rec.tobytes())


@pytest.mark.parametrize("level", [0, 1, 2])
def test_ksplat_levels_round_trip(tmp_path, level):
    rng = np.random.default_rng(level)
    n = 8
    means = rng.uniform(-1, 1, (n, 3))
    scales = rng.uniform(0.01, 0.5, (n, 3))
    quats = rng.normal(size=(n, 4))
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    rgba = rng.integers(0, 256, (n, 4), dtype=np.uint8)
    sh_rest = rng.uniform(-1, 1, (n, 9))
    path = tmp_path / "s.ksplat"
    write_ksplat(path, level, means, scales, quats, rgba, sh_rest)
    scene = ksplat.read(path)
    assert (scene.count, scene.sh_degree) == (n, 1)
    tol = 1e-6 if level == 0 else 2.0 / 32767 + 1e-6
    assert np.abs(scene.means - means).max() <= tol
    assert np.allclose(scene.scales, scales, rtol=1e-3)
    assert np.allclose(scene.rotations * np.sign(scene.rotations[:, :1]),
                       quats * np.sign(quats[:, :1]), atol=2e-3)
    assert np.allclose(scene.sh[:, 0], (rgba[:, :3] / 255 - 0.5) / SH_C0, atol=1e-5)
    sh_tol = {0: 1e-6, 1: 1e-3, 2: 4 / 255}[level]
    assert np.abs(scene.sh[:, 1:].reshape(n, 9) - sh_rest).max() <= sh_tol


def test_ksplat_bad_headers(tmp_path, shared_scenes):
    data = bytearray((shared_scenes / "fixtures/minimal.ksplat").read_bytes())
    path = tmp_path / "b.ksplat"
    huge = bytearray(data)
    struct.pack_into("<I", huge, 4, 0xFFFFFFFF)
    path.write_bytes(huge)
    with pytest.raises(SceneFormatError, match="section headers"):
        ksplat.read(path)
    level = bytearray(data)
    struct.pack_into("<H", level, 20, 3)
    path.write_bytes(level)
    with pytest.raises(SceneFormatError, match="compression level 3"):
        ksplat.read(path)
    path.write_bytes(data[:-5])
    with pytest.raises(SceneFormatError, match="truncated"):
        ksplat.read(path)


# --- detection --------------------------------------------------------------------------------

OWNERS = {"compressed_ply": compressed_ply, "spz": spz, "ksplat": ksplat}
ALL_FILES = {"compressed_ply/biker.compressed.ply": "compressed_ply",
             "fixtures/test64_sh3.compressed.ply": "compressed_ply",
             "spz/biker_v4.spz": "spz", "spz/donut_sh0_v2.spz": "spz",
             "fixtures/minimal-v2.spz": "spz", "fixtures/minimal-raw.spz": "spz",
             "fixtures/minimal.ksplat": "ksplat", "fixtures/minimal.splat": None,
             "ply/donut_sh0.ply": None}


@pytest.mark.parametrize("name,owner", ALL_FILES.items())
def test_only_the_owning_module_sniffs_a_file(shared_scenes, name, owner):
    head = (shared_scenes / name).read_bytes()[:4096]
    claims = {key for key, mod in OWNERS.items() if mod.sniff(head)}
    assert claims == ({owner} if owner else set())
