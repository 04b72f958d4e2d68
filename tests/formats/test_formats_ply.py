"""PLY and .splat reading/writing: encodings, SH layout, surfels, round trips, real files."""

from __future__ import annotations

import hypothesis.extra.numpy as hnp
import hypothesis.strategies as st
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings

from splatgl.constants import SH_C0, sh_coeff_count
from splatgl.formats import detect_format, load_scene, ply, ply_write, splat
from splatgl.scene.splats import Scene, SplatKind

from helpers import random_scene

FIELDS = ("means", "quats", "log_scales", "opacity_logits", "sh")


def assert_same_bits(a: Scene, b: Scene) -> None:
    assert a.kind is b.kind
    for name in FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        assert x.shape == y.shape, name
        assert x.dtype == y.dtype == np.float32, name
        assert x.tobytes() == y.tobytes(), f"{name} differs"


@pytest.mark.parametrize("degree", [0, 1, 2, 3])
def test_binary_le_be_and_ascii_load_identically_and_bit_exact(tmp_path, degree):
    scene = random_scene(17, degree, degree=degree)
    loaded = []
    for label, kwargs in [("le", {}), ("be", {"byte_order": "big"}), ("ascii", {"ascii": True})]:
        path = tmp_path / f"{label}.ply"
        ply_write.write(path, scene, **kwargs)
        loaded.append(load_scene(path))
    head = (tmp_path / "be.ply").read_bytes()[:60]
    assert b"binary_big_endian" in head
    assert b"format ascii 1.0" in (tmp_path / "ascii.ply").read_bytes()[:60]
    for got in loaded:
        assert_same_bits(got, scene)
        assert got.sh_degree == degree


def test_writer_uses_inria_property_order(tmp_path):
    path = tmp_path / "s.ply"
    ply_write.write(path, random_scene(3, 1, degree=1))
    header = path.read_bytes().split(b"end_header")[0].decode()
    props = [line.split()[2] for line in header.splitlines() if line.startswith("property")]
    assert props == (["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
                     + [f"f_rest_{i}" for i in range(9)]
                     + ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2",
                        "rot_3"])
    assert all(f"property float {p}" in header for p in props)
    assert len(path.read_bytes()) - len(header) - len("end_header\n") == 3 * 4 * len(props)


@pytest.mark.parametrize("degree", [1, 2, 3])
def test_f_rest_is_channel_major(tmp_path, degree):
    """f_rest holds all red coefficients, then green, then blue; file order does not matter."""
    k1 = sh_coeff_count(degree) - 1
    verts = ply_write.scene_to_vertices(random_scene(2, 5, degree=degree))
    for i in range(3 * k1):
        verts[f"f_rest_{i}"] = 1000 + i
    names = list(verts.dtype.names)
    shuffled = names[::-1]  # properties in reverse order: the reader must go by name
    path = tmp_path / "rest.ply"
    ply_write.write_elements(path, [("vertex", verts[shuffled])])
    scene = load_scene(path)
    assert scene.sh.shape == (2, k1 + 1, 3)
    # coefficient j (1-based after DC) of channel c is f_rest_{c * k1 + j - 1}
    assert scene.sh[0, 1, 0] == 1000            # first red coefficient
    assert scene.sh[0, 1, 1] == 1000 + k1       # first green coefficient
    assert scene.sh[1, k1, 2] == 1000 + 3 * k1 - 1  # last blue coefficient
    assert scene.sh[0, 2, 0] == 1001
    np.testing.assert_array_equal(scene.sh[:, 0], np.stack([verts[f"f_dc_{c}"] for c in range(3)],
                                                           axis=1))


@pytest.mark.parametrize("normals", [True, False])
def test_with_and_without_normals(tmp_path, normals):
    scene = random_scene(17, 7)
    path = tmp_path / "n.ply"
    ply_write.write(path, scene, normals=normals)
    assert (b"property float nx" in path.read_bytes()[:400]) == normals
    assert_same_bits(load_scene(path), scene)


def test_two_scales_make_a_2dgs_surfel_scene(tmp_path):
    scene = random_scene(17, 8, degree=1, kind=SplatKind.SURFEL_2D)
    path = tmp_path / "surfels.ply"
    ply_write.write(path, scene)
    header = path.read_bytes()[:600]
    assert b"scale_1" in header and b"scale_2" not in header
    got = load_scene(path)
    assert got.kind is SplatKind.SURFEL_2D
    assert got.log_scales.shape == (scene.count, 2)
    assert_same_bits(got, scene)


def test_other_types_extra_properties_and_elements(tmp_path):
    """double/int properties are cast to float32; unknown properties and elements are skipped."""
    scene = random_scene(5, 9)
    verts = ply_write.scene_to_vertices(scene)
    dt = [(n, "<f8" if n in ("x", "opacity") else "<f4") for n in verts.dtype.names]
    dt += [("red", "u1"), ("segment", "<i2")]
    wide = np.zeros(len(verts), dt)
    for n in verts.dtype.names:
        wide[n] = verts[n]
    wide["red"] = 200
    before = np.zeros(3, [("a", "<u4"), ("b", "i1"), ("c", "<f8")])
    after = np.ones(2, [("id", "<i4")])
    for kwargs in [{}, {"byte_order": "big"}, {"ascii": True}]:
        path = tmp_path / "wide.ply"
        ply_write.write_elements(path, [("camera", before), ("vertex", wide), ("extra", after)],
                           comments=("made by a test",), **kwargs)
        assert_same_bits(load_scene(path), scene)


def test_type_aliases_are_accepted(tmp_path):
    scene = random_scene(4, 10)
    path = tmp_path / "alias.ply"
    ply_write.write(path, scene)
    data = path.read_bytes().replace(b"property float ", b"property float32 ")
    data = data.replace(b"comment", b"obj_info")
    path.write_bytes(data)
    assert_same_bits(load_scene(path), scene)


def test_list_element_after_vertices_is_ignored(tmp_path):
    scene = random_scene(4, 11)
    path = tmp_path / "faces.ply"
    ply_write.write(path, scene)
    head, body = path.read_bytes().split(b"end_header\n")
    head += b"element face 1\nproperty list uchar int vertex_indices\n"
    face = bytes([3]) + np.arange(3, dtype="<i4").tobytes()
    path.write_bytes(head + b"end_header\n" + body + face)
    assert_same_bits(load_scene(path), scene)


def test_detection_is_by_content(tmp_path):
    scene = random_scene(17, 12)
    path = tmp_path / "scene.bin"
    ply_write.write(path, scene)
    assert detect_format(path) is ply
    assert_same_bits(load_scene(path), scene)
    assert ply.sniff(path.read_bytes()[:4096])
    assert not ply.sniff(b"ply\nformat binary_little_endian 1.0\nelement chunk 1\n"
                         b"property float min_x\nelement vertex 256\n"
                         b"property uint packed_position\nend_header\n")
    assert not ply.sniff(b"\x00" * 64)
    assert not splat.sniff((tmp_path / "scene.bin").read_bytes())


def test_a_missing_format_module_is_an_error():
    """A format module that cannot be imported (a broken install) is the import error, not a
    format silently left out of detection and writing."""
    from splatgl.formats import _modules

    with pytest.raises(ModuleNotFoundError, match="no_such_format"):
        _modules(("ply", "no_such_format"))


def test_real_donut_ply(shared_scenes):
    scene = load_scene(shared_scenes / "ply" / "donut_sh0.ply")
    assert scene.count == 45_624
    assert scene.sh_degree == 0
    assert scene.kind is SplatKind.GAUSSIAN_3D
    raw = np.linalg.norm(scene.quats.astype(np.float64), axis=1)
    assert raw.min() < 0.9 and raw.max() > 1.1  # trainer output is not normalised
    np.testing.assert_allclose(np.linalg.norm(scene.rotations.astype(np.float64), axis=1), 1.0,
                               atol=1e-6)
    assert np.ptp(scene.means, axis=0).max() < 0.5  # the object is about 0.2 units across


def test_real_donut_round_trips(shared_scenes, tmp_path):
    scene = load_scene(shared_scenes / "ply" / "donut_sh0.ply")
    path = tmp_path / "donut.ply"
    ply_write.write(path, scene)
    assert_same_bits(load_scene(path), scene)


def test_minimal_splat_fixture(shared_scenes):
    path = shared_scenes / "fixtures" / "minimal.splat"
    scene = load_scene(path)
    assert scene.count == 4 and scene.sh_degree == 0
    np.testing.assert_array_equal(scene.means, [[-1, 0, -1], [0, 0, -1], [-1, 0, 0], [0, 0, 0]])
    np.testing.assert_allclose(scene.scales, 0.1, rtol=1e-6)
    np.testing.assert_allclose(scene.opacities, 230 / 255, rtol=1e-6)
    np.testing.assert_allclose(0.5 + SH_C0 * scene.sh[0, 0], [85 / 255, 85 / 255, 128 / 255],
                               rtol=1e-6)
    # Re-encoding gives the same bytes, except scales (exp(log(s)) in float32: 1 ulp).
    raw = np.fromfile(path, splat.ROW_DTYPE)
    again = splat.encode(scene)
    for name in ("position", "rgba", "rotation"):
        np.testing.assert_array_equal(again[name], raw[name])
    np.testing.assert_allclose(again["scale"], raw["scale"], rtol=1e-6)


def test_splat_write_read_within_quantisation(tmp_path):
    scene = random_scene(50, 13)
    path = tmp_path / "s.splat"
    splat.write(path, scene)
    assert path.stat().st_size == 32 * 50
    got = load_scene(path)
    np.testing.assert_array_equal(got.means, scene.means)
    np.testing.assert_allclose(got.scales, scene.scales, rtol=1e-5)
    np.testing.assert_allclose(got.opacities, scene.opacities, atol=0.5 / 255 + 1e-6)
    colour = lambda s: np.clip(0.5 + SH_C0 * s.sh[:, 0], 0, 1)  # noqa: E731
    np.testing.assert_allclose(colour(got), colour(scene), atol=0.5 / 255 + 1e-6)
    # q and -q are the same rotation; compare |dot| of unit quaternions
    dot = np.abs((got.rotations.astype(np.float64) * scene.rotations).sum(axis=1))
    assert dot.min() > 0.999
    # A second pass keeps colour and alpha bytes; rotation bytes move by at most 1 (the decoded
    # quaternion is renormalised before it is quantised again).
    splat.write(tmp_path / "again.splat", got)
    first, second = (np.fromfile(p, splat.ROW_DTYPE) for p in (path, tmp_path / "again.splat"))
    np.testing.assert_array_equal(second["rgba"], first["rgba"])
    assert np.abs(second["rotation"].astype(int) - first["rotation"]).max() <= 1


def test_splat_writer_drops_sh_with_warning_and_refuses_surfels(tmp_path):
    with pytest.warns(UserWarning, match="SH degree 0 only"):
        splat.write(tmp_path / "a.splat", random_scene(17, 14, degree=2))
    from splatgl.errors import SceneFormatError
    with pytest.raises(SceneFormatError, match="surfel"):
        splat.write(tmp_path / "b.splat", random_scene(17, 15, kind=SplatKind.SURFEL_2D))


@settings(max_examples=25, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(values=hnp.arrays(np.float32, (6, 14),
                         elements=st.floats(width=32, allow_nan=False, allow_infinity=False)))
def test_any_finite_float32_round_trips_in_every_encoding(tmp_path, values):
    """Bit-exact for every finite float32 (-0.0, subnormals, extremes), binary and ASCII."""
    values[:, 7] = np.where(np.abs(values[:, 7]) < 1e-3, 1.0, values[:, 7])  # w keeps q nonzero
    scene = Scene(values[:, 0:3], values[:, 7:11], values[:, 11:14], values[:, 3],
                  values[:, 4:7].reshape(6, 1, 3))
    for kwargs in [{}, {"byte_order": "big"}, {"ascii": True}]:
        path = tmp_path / "h.ply"
        ply_write.write(path, scene, **kwargs)
        assert_same_bits(load_scene(path), scene)
