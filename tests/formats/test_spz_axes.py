"""SPZ axes (splatgl.formats.spz_axes): the extension record, the option, the version default.

The rule: a file's SPZ_ADOBE_coordinate_system record decides; else ``axes`` / --spz-axes;
else RUB for versions 3-4 (the SPZ specification) and the stored axes for versions 1-2.  The
interoperability with splat-transform 2.7.1 / 3.7.0 and the official library is tested in
tests/formats/test_interop_splat_transform.py (npm).
"""

from __future__ import annotations

import gzip
import itertools
import json
import struct
import warnings

import numpy as np
import pytest

from helpers import shared_file
from splatgl.cli import main
from splatgl.formats.convert import conversion_error
from splatgl.errors import SceneFormatError, SplatglError
from splatgl.formats import load_scene, save_scene, spz, spz_axes, spz_write
from splatgl.splatmath.project import sh_basis
from splatgl.scene.quaternion import quat_to_rotmat
from splatgl.scene.splats import Scene

SIGNS = [np.array(s, np.float64) for s in itertools.product((1.0, -1.0), repeat=3)]


def random_scene(n: int = 40, degree: int = 3, seed: int = 0) -> Scene:
    rng = np.random.default_rng(seed)
    return Scene(rng.uniform(-2, 2, (n, 3)), rng.normal(size=(n, 4)), rng.normal(-3, 0.5, (n, 3)),
                 rng.normal(0, 1, n), rng.normal(0, 0.2, (n, (degree + 1) ** 2, 3)))


def record(code: int, payload: bytes | None = None) -> bytes:
    payload = struct.pack("<I", code) if payload is None else payload
    return struct.pack("<II", spz_axes.EXT_COORDINATE_SYSTEM, len(payload)) + payload


def with_records(body: bytes, records: bytes) -> bytes:
    """A raw version 1-3 body (no records of its own) with flags bit 1 and ``records`` after."""
    return body[:14] + bytes([body[14] | spz.FLAG_EXTENSIONS]) + body[15:] + records


def v4_with_records(data: bytes, records: bytes) -> bytes:
    """A version 4 file with ``records`` between its header and table (tocByteOffset moved)."""
    head = bytearray(data[:32])
    head[14] |= spz.FLAG_EXTENSIONS
    struct.pack_into("<I", head, 16, 32 + len(records))
    return bytes(head) + records + data[32:]


@pytest.mark.parametrize("signs", SIGNS, ids=lambda s: "".join("+" if v > 0 else "-" for v in s))
def test_flip_axes_is_the_mirrored_scene(signs):
    """Covariance M S M, SH colour f(M d) and means M p for M = diag(signs), all 8 systems."""
    s = random_scene(30)
    means, quats, sh = s.means.astype(np.float64), s.rotations.astype(np.float64), s.sh.copy()
    spz_axes.flip_axes(means, quats, sh, signs)
    m = np.diag(signs)
    np.testing.assert_allclose(means, s.means * signs, atol=1e-6)
    r0, r1 = quat_to_rotmat(s.rotations.astype(np.float64)), quat_to_rotmat(quats)
    d2 = np.exp(2.0 * s.log_scales.astype(np.float64))[:, None, :]
    cov0 = np.einsum("nij,njk->nik", r0 * d2, r0.transpose(0, 2, 1))
    cov1 = np.einsum("nij,njk->nik", r1 * d2, r1.transpose(0, 2, 1))
    np.testing.assert_allclose(cov1, m @ cov0 @ m, rtol=1e-5, atol=1e-12)
    dirs = np.random.default_rng(1).normal(size=(30, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    colour = lambda coeffs, d: np.einsum("nk,nkc->nc", sh_basis(d, 3), coeffs)  # noqa: E731
    np.testing.assert_allclose(colour(sh, dirs * signs), colour(s.sh, dirs), atol=1e-5)


def test_letters_follow_the_library_enum():
    """Enum bits (value - 1): bit 0 L/R, bit 1 D/U, bit 2 B/F (splat-types.h ``axesMatch``)."""
    for code, name in enumerate(spz_axes.COORDINATE_SYSTEMS[1:9], start=1):
        bits = code - 1
        assert name == "LR"[bits & 1] + "DU"[bits >> 1 & 1] + "BF"[bits >> 2 & 1]
    assert list(spz_axes.axis_signs("RUB")) == [1, -1, -1]
    assert spz_axes.COORDINATE_SYSTEMS.index("RDF") == 6


@pytest.mark.parametrize("version,axes,stored,recorded", [
    (3, None, "RUB", False), (3, "rub", "RUB", False), (3, "rdf", "RDF", True),
    (2, None, "RDF", True), (2, "rub", "RUB", True), (2, "rdf", "RDF", True)])
def test_writer_records_its_axes_and_reads_back(tmp_path, version, axes, stored, recorded):
    s = random_scene(50, degree=2)
    path = tmp_path / "s.spz"
    spz_write.write(path, s, version=version, axes=axes)
    body = gzip.decompress(path.read_bytes())
    assert bool(body[14] & spz.FLAG_EXTENSIONS) == recorded
    if recorded:
        assert body.endswith(spz_axes.encode_record(stored))
    got = spz.read_axes(path)
    assert (got.stored, got.source) == (stored, "extension" if recorded else "default")
    raw = spz.read_spz(path, axes="rdf") if not recorded else None
    if raw is not None:  # no record: the bytes hold the mirrored scene
        np.testing.assert_allclose(raw.means, s.means * spz_axes.axis_signs(stored), atol=1e-3)
    e = conversion_error(s, load_scene(path))
    bounds = spz_write.error_bounds(s, version)
    for name in ("position", "rotation", "sh_rest"):
        assert e[name]["max"] <= bounds[name], name


@pytest.mark.parametrize("version", [2, 3])
def test_reader_honours_the_record_in_gzip_and_raw_bodies(tmp_path, version):
    s = random_scene(20, degree=1)
    body = spz_write.encode(s, version=version, axes="rub")  # bytes hold RUB
    body = body[:-len(spz_axes.encode_record("RUB"))] if body[14] & 2 else body
    path = tmp_path / "s.spz"
    for code, name in ((4, "RUB"), (6, "RDF"), (1, "LDB"), (8, "RUF")):
        raw = with_records(body, record(code))
        for data in (gzip.compress(raw), raw):
            path.write_bytes(data)
            got = load_scene(path)
            expect = s.means * spz_axes.axis_signs("RUB") * spz_axes.axis_signs(name)
            np.testing.assert_allclose(got.means, expect, atol=1e-3)
            assert spz.read_axes(path).stored == name


def test_reader_honours_the_record_in_version_4(tmp_path, shared_scenes):
    data = shared_file(shared_scenes, "fixtures/minimal-v4.spz").read_bytes()
    plain = tmp_path / "plain.spz"
    plain.write_bytes(data)
    rub = load_scene(plain)  # RUB by the specification: flipped to RDF
    path = tmp_path / "rdf.spz"
    path.write_bytes(v4_with_records(data, record(6)))
    np.testing.assert_allclose(load_scene(path).means, rub.means * [1, -1, -1], atol=1e-6)
    assert spz.read_axes(path).source == "extension"
    path.write_bytes(v4_with_records(data, record(4)))  # RUB recorded: same as unrecorded
    np.testing.assert_allclose(load_scene(path).means, rub.means, atol=1e-6)


def test_option_applies_only_where_the_file_records_nothing(tmp_path):
    s = random_scene(10, degree=0)
    path = tmp_path / "s.spz"
    save_scene(path, s)  # version 3, RUB, no record
    np.testing.assert_allclose(load_scene(path, spz_axes="rdf").means, s.means * [1, -1, -1],
                               atol=1e-3)
    assert spz.read_axes(path, "rdf").source == "option"
    save_scene(path, s, axes="rdf")  # recorded: the option is ignored, with a warning
    with pytest.warns(UserWarning, match="--spz-axes rub ignored: the file records its axes"):
        got = load_scene(path, spz_axes="rub")
    np.testing.assert_allclose(got.means, s.means, atol=1e-3)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_scene(path, spz_axes="rdf")  # agreeing: no warning


def test_unknown_and_unspecified_records(tmp_path):
    body = spz_write.encode(random_scene(5, degree=0), version=3)
    orbit = struct.pack("<II", spz_axes.EXT_SAFE_ORBIT_CAMERA, 12) + b"\0" * 12
    other = struct.pack("<II", 0x4E410001, 3) + b"abc"
    path = tmp_path / "s.spz"
    path.write_bytes(gzip.compress(with_records(body, orbit + other + record(0))))
    got = spz.read_axes(path)
    assert (got.stored, got.source) == ("RUB", "default")  # UNSPECIFIED = absent
    assert got.extensions == ("SPZ_ADOBE_safe_orbit_camera", "0x4e410001",
                              "SPZ_ADOBE_coordinate_system")
    assert load_scene(path).count == 5


@pytest.mark.parametrize("records,fragment", [
    (b"\x03\x00", "2 stray bytes"),
    (struct.pack("<II", 0xADBE0003, 9) + b"\0" * 4, "claims 9 bytes, only 4 follow"),
    (record(0, b"\x06\0"), "payload of 2 bytes, expected 4"),
    (record(17), "value 17 is not a coordinate system"),
    (record(12), "RFU (12): the rotated systems"),
    (record(6) + record(4), "2 SPZ_ADOBE_coordinate_system records"),
])
def test_bad_records_are_one_line_errors(tmp_path, capsys, records, fragment):
    body = spz_write.encode(random_scene(5, degree=0), version=3)
    path = tmp_path / "bad.spz"
    path.write_bytes(gzip.compress(with_records(body, records)))
    with pytest.raises(SceneFormatError, match="field 'extensions'") as err:
        load_scene(path)
    assert fragment in str(err.value) and str(path) in str(err.value)
    assert main(["info", str(path)]) == 2
    assert capsys.readouterr().err.count("\n") == 1


def test_bounds_on_the_extension_zone(tmp_path, shared_scenes):
    body = spz_write.encode(random_scene(5, degree=0), version=3)
    path = tmp_path / "s.spz"
    path.write_bytes(gzip.compress(body + record(6)))  # records without flags bit 1
    with pytest.raises(SceneFormatError, match="numPoints"):
        load_scene(path)
    big = struct.pack("<II", 0x4E410001, spz_axes.MAX_EXTENSION_BYTES) + bytes(
        spz_axes.MAX_EXTENSION_BYTES)
    path.write_bytes(gzip.compress(with_records(body, big)))
    with pytest.raises(SceneFormatError, match="extension records"):
        load_scene(path)
    data = shared_file(shared_scenes, "fixtures/minimal-v4.spz").read_bytes()
    bad = bytearray(v4_with_records(data, record(6)))
    struct.pack_into("<I", bad, 16, len(bad) + 1)
    path.write_bytes(bytes(bad))
    with pytest.raises(SceneFormatError, match="tocByteOffset"):
        load_scene(path)


def test_choice_is_checked_before_reading(tmp_path):
    with pytest.raises(SplatglError, match="--spz-axes must be one of rub, rdf"):
        spz_write.write(tmp_path / "x.spz", random_scene(3), axes="luf")
    assert not (tmp_path / "x.spz").exists()
    ply = tmp_path / "s.ply"
    save_scene(ply, random_scene(3))
    with pytest.raises(SplatglError, match="applies to SPZ files only"):
        load_scene(ply, spz_axes="rdf")


def test_shared_files_keep_their_default_axes(shared_scenes):
    """biker_v4.spz (PlayCanvas) is RUB; donut_sh0_v2.spz (spz-js) is as stored."""
    for name, stored in (("spz/biker_v4.spz", "RUB"), ("spz/donut_sh0_v2.spz", "RDF"),
                         ("fixtures/minimal-v3.spz", "RUB"), ("fixtures/minimal-v2.spz", "RDF")):
        got = spz.read_axes(shared_file(shared_scenes, name))
        assert (got.stored, got.source, got.extensions) == (stored, "default", ())


def test_cli_says_how_the_axes_were_read(tmp_path, capsys):
    src = tmp_path / "in.ply"
    save_scene(src, random_scene(200, degree=1))
    out = tmp_path / "out.spz"
    assert main(["convert", str(src), str(out), "--spz-axes", "rdf"]) == 0
    text = capsys.readouterr().out
    assert ("SPZ axes of the output: RDF (recorded by its SPZ_ADOBE_coordinate_system "
            "extension), read as is") in text and "(bound" in text and " !" not in text
    assert main(["info", str(out), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["spz_axes"]["source"] == "extension"
    plain = tmp_path / "plain.spz"
    assert main(["convert", str(src), str(plain)]) == 0
    capsys.readouterr()
    assert main(["info", str(plain), "--spz-axes", "rdf"]) == 0
    assert "axes:        RDF (--spz-axes rdf; the file records no axes)" in capsys.readouterr().out
    assert main(["convert", str(plain), str(tmp_path / "back.ply"), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["input_spz_axes"]["stored"] == "RUB" and result["output_spz_axes"] is None
    assert main(["convert", str(src), str(tmp_path / "x.ply"), "--spz-axes", "rdf"]) == 2
    assert "--spz-axes applies to .spz files only" in capsys.readouterr().err


def test_rendering_commands_take_the_option_but_not_to_workers(tmp_path, capsys):
    import argparse

    from splatgl.commands._common import load_scene_arg

    s = random_scene(20, degree=0)
    path = tmp_path / "s.spz"
    save_scene(path, s)  # version 3, RUB, no record
    args = argparse.Namespace(scene=path, drop_invalid=False, spz_axes="rdf")
    np.testing.assert_allclose(load_scene_arg(args).means, s.means * [1, -1, -1], atol=1e-3)
    assert main(["render", str(path), "--spz-axes", "rdf", "--path", "orbit:2", "--workers", "2",
                 "-o", str(tmp_path / "f%02d.png"), "--width", "16", "--height", "16"]) == 2
    err = capsys.readouterr().err
    assert "--spz-axes does not reach --workers" in err and err.count("\n") == 1
    assert not list(tmp_path.glob("f*.png"))
