"""SOG, glTF, SPZ-write and compressed-PLY-write specifics: quantisation bounds against their
derivations, axis conventions, SOG v1 and folder forms, glTF schema, node transforms, the SPZ
compression extension, and the convert CLI's report."""

from __future__ import annotations

import base64
import json
import math
from pathlib import Path

import numpy as np
import pytest

from splatgl.cli import main
from splatgl.formats.convert import conversion_error
from splatgl.formats import compressed_ply_write, load_scene, save_scene, sog, sog_write, spz_write
from splatgl.formats import quantise as qz
from splatgl.scene.splats import Scene

from helpers import random_scene

SCHEMA_DIR = Path(__file__).parents[1] / "data" / "gltf_schema"


def test_quantisation_constants_and_bounds():
    # SPZ: 12 fractional bits -> half a step per axis, sqrt(3) of it as a distance
    s = random_scene(100, degree=1)
    b = spz_write.error_bounds(s)
    assert b["position"] == pytest.approx(
        math.sqrt(3) * 0.5 / 4096 + qz.position_slack(s.means), rel=1e-12)
    assert spz_write.fractional_bits(np.array([[3000.0, 0, 0]])) == 11  # 2^23 / 2^12 = 2048
    # compressed PLY: 11-10-11 bits inside a chunk
    one = Scene(np.array([[0, 0, 0], [2047, 1023, 2047]], np.float32), np.tile([1, 0, 0, 0], (2, 1)),
                np.zeros((2, 3)), np.zeros(2), np.zeros((2, 1, 3)))
    assert compressed_ply_write.error_bounds(one)["position"] == pytest.approx(
        math.sqrt(3) * 0.5 + qz.position_slack(one.means), rel=1e-9)
    # smallest-three: 8-bit SOG components -> 4 sqrt(3) e (5% margin) in radians
    e = 1 / (255 * math.sqrt(2))
    assert sog_write.error_bounds(s)["rotation"] == pytest.approx(
        math.degrees(4 * math.asin(1.05 * math.sqrt(3) * e)), rel=1e-9)
    assert sog_write.palette_size(64) == 64 and sog_write.palette_size(40_000) == 32768
    assert sog_write.palette_size(10_000_000) == 65536


def test_codebook_bound_is_half_the_largest_gap():
    values = np.random.default_rng(0).standard_t(3, 20000)
    book = qz.codebook_1d(values)
    assert book.size == 256 and book[0] == values.min() and book[-1] == values.max()
    err = np.abs(book[qz.codebook_labels(values, book)] - values).max()
    assert err <= qz.codebook_bound(book, values)
    assert qz.codebook_bound(book, values) == pytest.approx(0.5 * np.diff(book).max(), rel=1e-5)


@pytest.mark.parametrize("degree", [0, 1, 3])
@pytest.mark.parametrize("name", ["a.sog", "meta.json", "a.glb", "a.gltf", "a.compressed.ply",
                                  "a.spz"])
def test_round_trip_within_bounds(tmp_path, name, degree):
    s = random_scene(3000, degree=degree, seed=degree)
    order = save_scene(tmp_path / name, s)
    back = load_scene(tmp_path / name)
    a = s if order is None else s.subset(order)
    e = conversion_error(a, back)
    from splatgl.formats import writer_for
    bounds = writer_for(tmp_path / name).error_bounds(s)
    for attr, bound in bounds.items():
        if bound is not None and e[attr] is not None:
            assert e[attr]["max"] <= bound, attr
    if name in ("a.sog", "meta.json") and degree:  # palette error: stated, far below the spread
        assert e["sh_rest"]["mean"] < 0.5 * np.abs(a.sh[:, 1:]).mean()


@pytest.mark.parametrize("version", [2, 3])
def test_spz_sh_bound_covers_clipping_of_flipped_signs(tmp_path, version):
    """SH bytes hold [-1, 127/128]; version 3 stores RUB, negating the odd coefficients first,
    so -1.3 on one of them is clipped at +127/128 in the file: the bound must say 1.3 - 127/128,
    not the 0.3 of an unflipped -1.3."""
    scene = random_scene(4, degree=1)
    sh = scene.sh.copy()
    sh[:, 1:] = 0.0
    sh[0, 1, 0] = -1.3  # coefficient 1 (y): negated by the flip
    scene = Scene(scene.means, scene.quats, scene.log_scales, scene.opacity_logits, sh)
    save_scene(tmp_path / "a.spz", scene, version=version)
    e = conversion_error(scene, load_scene(tmp_path / "a.spz"))
    bound = spz_write.error_bounds(scene, version)["sh_rest"]
    assert e["sh_rest"]["max"] <= bound < e["sh_rest"]["max"] + 0.5 / qz.SPZ_SH_SCALE + 1e-5
    assert e["sh_rest"]["max"] == pytest.approx(1.3 - 127 / 128 if version == 3 else 0.3, abs=1e-6)


def test_sog_folder_has_its_textures_and_no_partials(tmp_path):
    save_scene(tmp_path / "meta.json", random_scene(200, degree=1))
    names = sorted(p.name for p in tmp_path.iterdir())
    assert sog.stored_bytes(tmp_path / "meta.json") == sum(p.stat().st_size
                                                          for p in tmp_path.iterdir())
    assert names == sorted(["meta.json", "means_l.webp", "means_u.webp", "quats.webp",
                            "scales.webp", "sh0.webp", "shN_centroids.webp", "shN_labels.webp"])


def test_sog_v1_meta_is_read(tmp_path):
    """A v1 meta.json (min/max ranges, no codebooks) built over v2 textures of known values."""
    s = random_scene(100, degree=0)
    save_scene(tmp_path / "meta.json", s)
    meta = json.loads((tmp_path / "meta.json").read_text())
    # v1: byte b -> min + (max - min) b / 255; make the byte the label so values are known
    v1 = {"means": {"shape": [100, 3], "mins": meta["means"]["mins"],
                    "maxs": meta["means"]["maxs"], "files": meta["means"]["files"]},
          "scales": {"mins": [-10, -10, -10], "maxs": [0.2, 0.2, 0.2], "files": ["scales.webp"]},
          "quats": {"files": ["quats.webp"]},
          "sh0": {"mins": [-1, -1, -1, -5], "maxs": [1, 1, 1, 5], "files": ["sh0.webp"]}}
    (tmp_path / "meta.json").write_text(json.dumps(v1))
    v1_scene = load_scene(tmp_path / "meta.json")
    from PIL import Image
    labels = np.asarray(Image.open(tmp_path / "sh0.webp").convert("RGBA")).reshape(-1, 4)[:100].astype(np.float64)
    np.testing.assert_allclose(v1_scene.sh[:, 0], -1 + 2 * labels[:, :3] / 255.0, atol=1e-6)
    np.testing.assert_allclose(v1_scene.opacity_logits, -5 + 10 * labels[:, 3] / 255.0, atol=1e-5)


def test_gltf_axes_and_schema(tmp_path):
    jsonschema = pytest.importorskip("jsonschema")
    from referencing import Registry, Resource
    s = random_scene(50, degree=1)
    save_scene(tmp_path / "a.gltf", s)
    doc = json.loads((tmp_path / "a.gltf").read_text())
    prim = doc["meshes"][0]["primitives"][0]
    assert prim["mode"] == 0 and doc["extensionsUsed"] == ["KHR_gaussian_splatting"]
    schemas = {p.name: json.loads(p.read_text()) for p in SCHEMA_DIR.glob("*.schema.json")}
    registry = Registry().with_resources(
        (name, Resource.from_contents(body)) for name, body in schemas.items())
    validator = jsonschema.Draft202012Validator(
        schemas["mesh.primitive.KHR_gaussian_splatting.schema.json"], registry=registry)
    validator.validate(prim["extensions"]["KHR_gaussian_splatting"])
    with pytest.raises(jsonschema.ValidationError):
        validator.validate({"kernel": "ellipse"})  # colorSpace is required
    # POSITION is the scene turned 180 degrees about z; rotations unit, xyzw
    buf = base64.b64decode(doc["buffers"][0]["uri"].split(",", 1)[1])

    def accessor(name):
        acc = doc["accessors"][prim["attributes"][name]]
        view = doc["bufferViews"][acc["bufferView"]]
        width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4}[acc["type"]]
        return np.frombuffer(buf, "<f4", acc["count"] * width, view["byteOffset"]).reshape(-1, width)

    np.testing.assert_array_equal(accessor("POSITION"), s.means * [-1, -1, 1])
    np.testing.assert_allclose(np.linalg.norm(accessor("KHR_gaussian_splatting:ROTATION"), axis=1),
                               1, atol=1e-6)
    np.testing.assert_allclose(accessor("KHR_gaussian_splatting:SCALE"), s.scales, rtol=1e-6)
    dc = accessor("KHR_gaussian_splatting:SH_DEGREE_0_COEF_0")
    np.testing.assert_array_equal(dc, s.sh[:, 0])
    # degree 1 (y, z, x): y and x odd under the turn
    np.testing.assert_array_equal(accessor("KHR_gaussian_splatting:SH_DEGREE_1_COEF_0"), -s.sh[:, 1])
    np.testing.assert_array_equal(accessor("KHR_gaussian_splatting:SH_DEGREE_1_COEF_1"), s.sh[:, 2])
    assert doc["accessors"][prim["attributes"]["POSITION"]]["min"] == \
        accessor("POSITION").min(axis=0).tolist()


def test_gltf_node_transform_is_applied(tmp_path):
    s = random_scene(20, degree=0)
    save_scene(tmp_path / "a.gltf", s)
    doc = json.loads((tmp_path / "a.gltf").read_text())
    doc["nodes"][0].update(translation=[1, 2, 3], scale=[2, 2, 2],
                           rotation=[0, 0, math.sin(math.pi / 4), math.cos(math.pi / 4)])
    (tmp_path / "b.gltf").write_text(json.dumps(doc))
    t = load_scene(tmp_path / "b.gltf")
    g = s.means.astype(np.float64) * [-1, -1, 1]  # glTF axes
    rz = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]])
    expect = (2 * g @ rz.T + [1, 2, 3]) * [-1, -1, 1]
    np.testing.assert_allclose(t.means, expect, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(t.log_scales, s.log_scales + math.log(2), atol=1e-5)
    doc["nodes"][0]["scale"] = [1, 2, 3]
    (tmp_path / "c.gltf").write_text(json.dumps(doc))
    with pytest.raises(Exception, match="not uniform"):
        load_scene(tmp_path / "c.gltf")


def test_gltf_spz_compression_extension_is_read(tmp_path):
    s = random_scene(200, degree=1)
    body = __import__("gzip").compress(spz_write.encode(s, version=3))
    blob = body + b"\0" * (-len(body) % 4)   # the buffer is padded to 4 bytes, the view is not
    doc = {"asset": {"version": "2.0"}, "extensionsUsed": ["KHR_gaussian_splatting",
                                                            "KHR_gaussian_splatting_compression_spz_2"],
           "meshes": [{"primitives": [{"attributes": {}, "mode": 0, "extensions": {
               "KHR_gaussian_splatting": {"kernel": "ellipse", "colorSpace": "srgb_rec709_display",
                                          "extensions": {"KHR_gaussian_splatting_compression_spz_2":
                                                         {"bufferView": 0}}}}}]}],
           "buffers": [{"byteLength": len(blob), "uri": "data:application/octet-stream;base64,"
                        + base64.b64encode(blob).decode()}],
           "bufferViews": [{"buffer": 0, "byteLength": len(body)}]}
    (tmp_path / "c.gltf").write_text(json.dumps(doc))
    got = load_scene(tmp_path / "c.gltf")
    e = conversion_error(s, got)
    bounds = spz_write.error_bounds(s)
    assert e["position"]["max"] <= bounds["position"]
    assert e["sh_rest"]["max"] <= bounds["sh_rest"]
    assert e["rotation"]["max"] <= bounds["rotation"]


def test_spz_v3_stores_rub_axes_and_v2_as_is(tmp_path):
    s = random_scene(10, degree=0)
    for version, signs in ((3, [1, -1, -1]), (2, [1, 1, 1])):
        body = spz_write.encode(s, version=version)
        b = np.frombuffer(body[16:16 + 9 * 10], np.uint8).reshape(10, 3, 3).astype(np.int64)
        fixed = b[..., 0] | (b[..., 1] << 8) | (b[..., 2] << 16)
        fixed = np.where(fixed & 0x800000, fixed - (1 << 24), fixed)
        np.testing.assert_allclose(fixed / 4096.0, s.means * signs, atol=0.5 / 4096 + 1e-6)


def test_convert_cli_reports_bounds(tmp_path, capsys):
    src = tmp_path / "in.ply"
    save_scene(src, random_scene(500, degree=1))
    assert main(["convert", str(src), str(tmp_path / "out.sog")]) == 0
    out = capsys.readouterr().out
    assert "(bound " in out and " !" not in out and "wrote" in out
    assert main(["convert", str(src), str(tmp_path / "out.spz"), "--json",
                 "--spz-version", "2"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert all(result["error"]["within_bounds"].values())
    assert set(result["error"]["bounds"]) >= {"position", "rotation", "color"}
    assert main(["convert", str(src), str(tmp_path / "x.ply"), "--spz-version", "2"]) == 2
    assert "--spz-version applies to .spz output only" in capsys.readouterr().err
    assert main(["convert", str(src), str(tmp_path / "x.usdz")]) == 2
    err = capsys.readouterr().err
    assert "cannot write this format" in err and ".sog" in err and err.count("\n") == 1


def test_bad_new_inputs_are_one_line_errors(tmp_path, capsys):
    bad = tmp_path / "bad.sog"
    bad.write_bytes(b"PK\x03\x04meta.json garbage")
    assert main(["info", str(bad)]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and err.count("\n") == 1
    glb = tmp_path / "bad.glb"
    glb.write_bytes(b"glTF\x02\0\0\0\xff\0\0\0")
    assert main(["info", str(glb)]) == 2
    assert "truncated" in capsys.readouterr().err


@pytest.mark.parametrize("content, starts", [(b"hello world\n", "starts 'hello world\\x0a'"),
                                             (b"", "is empty")])
def test_a_sog_that_is_no_zip_says_so(tmp_path, capsys, content, starts):
    """A text file named x.sog was 'meta.json is not valid JSON': a file the user never gave."""
    bad = tmp_path / "x.sog"
    bad.write_bytes(content)
    assert main(["info", str(bad)]) == 2
    assert capsys.readouterr().err == (f"splatgl: error: {bad}: not a SOG bundle: a .sog file is "
                                       f"a zip archive (starting 'PK\\x03\\x04'), this one "
                                       f"{starts}\n")


def test_antialias_tags_turn_on_antialias(tmp_path, capsys):
    import argparse
    import gzip

    from splatgl.commands._common import antialias_from_args
    from splatgl.formats.metadata import antialias_tag

    s = random_scene(30, degree=0)
    tagged = tmp_path / "aa.spz"
    tagged.write_bytes(gzip.compress(spz_write.encode(s, antialiased=True)))
    plain = tmp_path / "plain.spz"
    save_scene(plain, s)
    ply = tmp_path / "mip.ply"
    save_scene(ply, s)
    ply.write_bytes(ply.read_bytes().replace(b"comment written by splatgl",
                                             b"comment SplatRenderMode: mip", 1))
    meta = tmp_path / "meta.json"
    save_scene(meta, s)
    doc = json.loads(meta.read_text())
    meta.write_text(json.dumps({**doc, "model": "antialiased"}))
    assert antialias_tag(tagged) == "SPZ header flag 'antialiased'"
    assert antialias_tag(ply) == "PLY comment 'SplatRenderMode: mip'"
    assert antialias_tag(meta) == "SOG meta.json model 'antialiased'"
    assert antialias_tag(plain) is None and antialias_tag(tmp_path / "none.ply") is None

    def ns(scene, flag=None):
        return argparse.Namespace(scene=scene, antialias=flag)

    assert antialias_from_args(ns(tagged)) is True
    assert "rendering with --antialias" in capsys.readouterr().err
    assert antialias_from_args(ns(tagged, False)) is False
    assert antialias_from_args(ns(plain)) is False and antialias_from_args(ns(None)) is False
    assert capsys.readouterr().err == ""
    assert load_scene(ply).count == 30  # the comment does not disturb reading


def test_a_repeated_json_key_in_gltf_or_sog_is_refused(tmp_path):
    """Issue 38: JSON keeps the last of a repeated key without a word (here the scene's own)."""
    import zipfile

    from helpers import random_scene
    from splatgl.errors import SceneFormatError

    gltf, sog = tmp_path / "a.gltf", tmp_path / "a.sog"
    save_scene(gltf, random_scene(3))
    gltf.write_text(gltf.read_text().replace('{"asset": ', '{"scene": 0, "asset": ', 1))
    with pytest.raises(SceneFormatError) as info:
        load_scene(gltf)
    assert str(info.value) == (f"{gltf}: glTF JSON is not valid: key 'scene' given twice in one "
                               "object (JSON keeps only the last)")
    save_scene(sog, random_scene(3))
    with zipfile.ZipFile(sog) as z:
        files = {name: z.read(name) for name in z.namelist()}
    files["meta.json"] = files["meta.json"].replace(b"{", b'{"count": 1, ', 1)
    with zipfile.ZipFile(sog, "w") as z:
        for name, data in files.items():
            z.writestr(name, data)
    with pytest.raises(SceneFormatError) as info:
        load_scene(sog)
    assert str(info.value) == (f"{sog}: meta.json is not valid JSON: key 'count' given twice in "
                               "one object (JSON keeps only the last)")


def test_convert_and_edit_count_a_sog_folders_textures(tmp_path, capsys):
    """The bytes ``convert`` and ``edit`` report for a SOG folder are the folder's (meta.json
    and its textures), not meta.json's alone (which the writer module cannot count)."""
    save_scene(tmp_path / "s.ply", random_scene(200, degree=1))
    out = tmp_path / "out"
    out.mkdir()
    assert main(["convert", str(tmp_path / "s.ply"), str(out / "meta.json")]) == 0
    total = sum(p.stat().st_size for p in out.iterdir())
    assert f"(sog, {total:,} bytes)" in capsys.readouterr().out
    assert main(["edit", str(tmp_path / "s.ply"), "-o", str(out / "meta.json"), "--force",
                 "--remove", "opacity < -100"]) == 0
    total = sum(p.stat().st_size for p in out.iterdir())
    assert f"({total:,} bytes)" in capsys.readouterr().out
