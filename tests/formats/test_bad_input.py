"""Every kind of bad scene file gives one clear SceneFormatError (and exit 2 from the CLI)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from splatgl.cli import main
from splatgl.errors import SceneFormatError
from splatgl.formats import load_scene, ply, ply_write, splat
from splatgl.scene.splats import Scene


def good_vertices(n: int = 10, seed: int = 0) -> np.ndarray:
    """(n,) INRIA vertex rows (structured float32) of a valid random scene."""
    rng = np.random.default_rng(seed)
    scene = Scene(rng.normal(size=(n, 3)), rng.normal(size=(n, 4)) + 0.1,
                  rng.normal(-3, 1, size=(n, 3)), rng.normal(size=n),
                  rng.normal(size=(n, 1, 3)))
    return ply_write.scene_to_vertices(scene)


def write_vertices(path, verts: np.ndarray, **kwargs):
    ply_write.write_elements(path, [("vertex", verts)], **kwargs)
    return path


def expect_error(path, *fragments: str, field: str | None = None) -> SceneFormatError:
    with pytest.raises(SceneFormatError) as info:
        load_scene(path)
    msg = str(info.value)
    assert str(path) in msg
    for frag in fragments:
        assert frag in msg, f"{frag!r} not in {msg!r}"
    if field is not None:
        assert info.value.field == field
        assert f"'{field}'" in msg
    return info.value


# ---------------------------------------------------------------- structure of the file


def test_truncated_binary_says_expected_and_found_bytes(tmp_path):
    path = write_vertices(tmp_path / "t.ply", good_vertices(10))
    row = good_vertices(1).dtype.itemsize
    path.write_bytes(path.read_bytes()[:-5])
    expect_error(path, "truncated", f"needs {10 * row} bytes", f"found {10 * row - 5}",
                 field="vertex")


def test_truncated_ascii_names_the_line(tmp_path):
    path = write_vertices(tmp_path / "t.ply", good_vertices(10), ascii=True)
    lines = path.read_text().splitlines()
    path.write_text("\n".join(lines[:-3]) + "\n")
    expect_error(path, "truncated", "declares 10 rows, found 7", "line")


def test_ascii_short_row_and_bad_number_name_the_line(tmp_path):
    path = write_vertices(tmp_path / "a.ply", good_vertices(4), ascii=True)
    lines = path.read_text().splitlines()
    header_lines = lines.index("end_header") + 1
    short = lines.copy()
    short[header_lines + 2] = " ".join(short[header_lines + 2].split()[:-1])
    path.write_text("\n".join(short) + "\n")
    expect_error(path, f"line {header_lines + 3}:", "values, expected")
    word = lines.copy()
    word[header_lines + 1] = "abc " + " ".join(word[header_lines + 1].split()[1:])
    path.write_text("\n".join(word) + "\n")
    expect_error(path, f"line {header_lines + 2}:", "'abc' is not a number", field="x")


def test_trailing_bytes_are_a_count_mismatch(tmp_path):
    path = write_vertices(tmp_path / "t.ply", good_vertices(10))
    path.write_bytes(path.read_bytes() + b"\0" * 62)
    expect_error(path, "62 bytes after the last element", "mismatch")
    asc = write_vertices(tmp_path / "a.ply", good_vertices(3), ascii=True)
    asc.write_text(asc.read_text() + "1 2 3\n\n")
    expect_error(asc, "1 non-empty line(s) after the last element")


def test_header_count_larger_than_data(tmp_path):
    path = write_vertices(tmp_path / "c.ply", good_vertices(10))
    path.write_bytes(path.read_bytes().replace(b"element vertex 10", b"element vertex 12"))
    expect_error(path, "truncated", "12 rows")


@pytest.mark.parametrize("prop", ["x", "z", "f_dc_1", "opacity", "scale_0", "rot_3"])
def test_missing_required_property_is_named(tmp_path, prop):
    verts = good_vertices(5)
    keep = [n for n in verts.dtype.names if n != prop]
    path = write_vertices(tmp_path / "m.ply", verts[keep])
    expect_error(path, "required vertex property missing", field=prop)


def test_bad_f_rest_count_and_gaps(tmp_path):
    verts = good_vertices(3)
    wide = np.zeros(3, verts.dtype.descr + [(f"f_rest_{i}", "<f4") for i in range(10)])
    for n in verts.dtype.names:
        wide[n] = verts[n]
    expect_error(write_vertices(tmp_path / "r.ply", wide), "10 properties found",
                 field="f_rest_*")
    gap = [n for n in wide.dtype.names if n != "f_rest_4"]
    expect_error(write_vertices(tmp_path / "g.ply", wide[gap]), "not numbered", field="f_rest_4")


def header_variant(tmp_path, old: bytes, new: bytes, name="h.ply"):
    path = write_vertices(tmp_path / name, good_vertices(4))
    data = path.read_bytes()
    assert old in data
    path.write_bytes(data.replace(old, new, 1))
    return path


def test_unsupported_format_line(tmp_path):
    path = header_variant(tmp_path, b"format binary_little_endian 1.0",
                          b"format binary_middle_endian 1.0")
    expect_error(path, "unsupported format line", field="format")
    path = header_variant(tmp_path, b"format binary_little_endian 1.0",
                          b"format ascii 2.0", name="v.ply")
    expect_error(path, "unsupported format line", field="format")


def test_missing_end_header(tmp_path):
    path = tmp_path / "e.ply"
    path.write_bytes(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n")
    expect_error(path, "end_header")


def test_bad_property_type(tmp_path):
    path = header_variant(tmp_path, b"property float opacity", b"property half opacity")
    expect_error(path, "unknown property type 'half'", field="opacity")


def test_list_property_in_element_before_vertices(tmp_path):
    path = write_vertices(tmp_path / "l.ply", good_vertices(4))
    head, body = path.read_bytes().split(b"end_header\n")
    head = head.replace(b"element vertex", b"element face 1\nproperty list uchar int idx\n"
                        b"element vertex")
    path.write_bytes(head + b"end_header\n" + b"\x01\x00\x00\x00\x00" + body)
    expect_error(path, "list properties", field="face")


def test_empty_scene(tmp_path):
    empty_rows = good_vertices(1)[:0]
    path = write_vertices(tmp_path / "empty.ply", empty_rows)
    expect_error(path, "no splats")
    for kwargs in ({"ascii": True}, {"byte_order": "big"}):
        expect_error(write_vertices(tmp_path / "empty.ply", empty_rows, **kwargs),
                     "no splats")
    empty = tmp_path / "empty.splat"
    empty.write_bytes(b"")
    expect_error(empty, "no splats")


def test_unknown_formats(tmp_path):
    rng = np.random.default_rng(3)
    noise = tmp_path / "noise.bin"
    noise.write_bytes(rng.integers(0, 256, 1000, dtype=np.uint8).tobytes())
    expect_error(noise, "unknown scene format")
    text = tmp_path / "notes.txt"
    text.write_text("this is a text file,\nnot a scene\n")
    expect_error(text, "unknown scene format")
    fake = tmp_path / "fake.ply"
    fake.write_bytes(noise.read_bytes())
    expect_error(fake, "not a PLY file")
    expect_error(tmp_path / "missing.ply", "no such file")


def test_compressed_ply_is_not_read_as_inria(tmp_path):
    path = tmp_path / "c.ply"
    path.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement chunk 1\n"
                     b"property float min_x\nelement vertex 1\nproperty uint packed_position\n"
                     b"end_header\n" + b"\0" * 8)
    with pytest.raises(SceneFormatError, match="compressed"):
        ply.read(path)


def test_splat_size_not_a_multiple_of_32(tmp_path):
    path = tmp_path / "bad.splat"
    path.write_bytes(b"\0" * (32 * 3 + 7))
    expect_error(path, "not a multiple of 32", "3 whole splats and 7 bytes left over")


# ---------------------------------------------------------------- invalid values


@pytest.mark.parametrize("prop,field,value", [
    ("y", "position", np.nan), ("f_dc_2", "sh", np.inf), ("opacity", "opacity", np.nan),
    ("scale_1", "scale", np.nan), ("rot_0", "rotation", np.nan),
])
def test_nan_and_inf_give_field_count_and_first_index(tmp_path, prop, field, value):
    verts = good_vertices(20)
    verts[prop][[4, 9, 15]] = value
    for kwargs in ({}, {"ascii": True}):
        path = write_vertices(tmp_path / f"nan{len(kwargs)}.ply", verts, **kwargs)
        expect_error(path, "3 row(s)", "NaN or Inf", "first at index 4", field=field)


def test_an_infinite_opacity_logit_is_opacity_one_or_zero(tmp_path):
    """splat-transform writes +Inf for opacity 1 (a compressed PLY's 255 turned into a PLY):
    such rows were refused as NaN or Inf, and --drop-invalid dropped the most opaque splats.
    +-Inf reads as +-30 (sigmoid 1 or 0 in float32), with one warning that counts them."""
    from splatgl.scene.opacity import OPAQUE_LOGIT

    verts = good_vertices(20)
    verts["opacity"][[4, 9]] = np.inf
    verts["opacity"][15] = -np.inf
    path = write_vertices(tmp_path / "inf.ply", verts)
    with pytest.warns(UserWarning, match=r"inf.ply: 3 of 20 rows read hold an infinite opacity"):
        scene = load_scene(path)
    assert scene.count == 20
    assert scene.opacity_logits[[4, 9, 15]].tolist() == [OPAQUE_LOGIT, OPAQUE_LOGIT, -OPAQUE_LOGIT]
    assert scene.opacities[[4, 9]].tolist() == [1.0, 1.0] and scene.opacities[15] < 1e-12
    import warnings

    from splatgl.scene.opacity import finite_logits

    with warnings.catch_warnings(record=True) as caught:   # a reader by blocks: said once a file
        warnings.simplefilter("always")
        for _ in range(3):
            block = finite_logits(tmp_path / "blocks.ply", np.array([0.5, np.inf], np.float32))
    assert len(caught) == 1 and block.tolist() == [0.5, OPAQUE_LOGIT]


@pytest.mark.parametrize("scale", [0.0, 1e-30])
def test_zero_and_degenerate_quaternions(tmp_path, scale):
    verts = good_vertices(8)
    for i in range(4):
        verts[f"rot_{i}"][[2, 6]] *= scale
    path = write_vertices(tmp_path / "q.ply", verts)
    expect_error(path, "2 row(s)", "zero or degenerate quaternion", "first at index 2",
                 field="rotation")


def test_splat_with_centred_rotation_bytes_is_degenerate(tmp_path):
    rows = np.zeros(3, splat.ROW_DTYPE)
    rows["scale"], rows["rgba"], rows["rotation"] = 0.1, 200, [255, 128, 128, 128]
    rows["rotation"][1] = 128
    path = tmp_path / "q.splat"
    rows.tofile(path)
    expect_error(path, "1 row(s)", "first at index 1", field="rotation")


def test_drop_invalid_warns_with_count_and_drops_rows(tmp_path):
    verts = good_vertices(12)
    verts["x"][3] = np.nan
    verts["opacity"][7] = np.nan
    for i in range(4):
        verts[f"rot_{i}"][10] = 0.0
    path = write_vertices(tmp_path / "d.ply", verts)
    with pytest.warns(UserWarning, match=r"dropped 3 invalid row\(s\) of 12"):
        scene = load_scene(path, drop_invalid=True)
    assert scene.count == 9
    keep = np.setdiff1d(np.arange(12), [3, 7, 10])
    np.testing.assert_array_equal(scene.means[:, 1], verts["y"][keep])


# ---------------------------------------------------------------- through the CLI


def run_cli(capsys, *argv):
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        rc = main(list(argv))
    out, err = capsys.readouterr()
    return rc, out, err


def test_cli_bad_file_exits_2_with_one_line(tmp_path, capsys):
    verts = good_vertices(6)
    verts["scale_2"][5] = np.nan
    bad = write_vertices(tmp_path / "bad.ply", verts)
    rc, out, err = run_cli(capsys, "info", str(bad))
    assert rc == 2
    assert out == ""
    assert len(err.strip().splitlines()) == 1
    assert str(bad) in err and "'scale'" in err and "first at index 5" in err
    assert "Traceback" not in err


@pytest.mark.parametrize("make", ["truncated", "missing", "noise"])
def test_cli_structural_errors_exit_2(tmp_path, capsys, make):
    path = write_vertices(tmp_path / "s.ply", good_vertices(6))
    if make == "truncated":
        path.write_bytes(path.read_bytes()[:-1])
    elif make == "missing":
        verts = good_vertices(6)
        write_vertices(path, verts[[n for n in verts.dtype.names if n != "rot_2"]])
    else:
        path.write_bytes(b"\x13\x37" * 100)
    rc, out, err = run_cli(capsys, "info", str(path))
    assert rc == 2 and len(err.strip().splitlines()) == 1
    assert str(path) in err and "Traceback" not in err
    if make == "missing":
        assert "rot_2" in err


def test_cli_drop_invalid_warns_and_succeeds(tmp_path, capsys):
    verts = good_vertices(6)
    verts["z"][[1, 2]] = np.inf
    path = write_vertices(tmp_path / "d.ply", verts)
    rc, out, err = run_cli(capsys, "info", str(path), "--drop-invalid", "--json")
    assert rc == 0
    assert "dropped 2 invalid row(s) of 6" in err and "Traceback" not in err
    assert '"count": 4' in out


def test_cli_info_on_real_scene(shared_scenes, capsys):
    rc, out, err = run_cli(capsys, "info", str(shared_scenes / "ply" / "donut_sh0.ply"))
    assert rc == 0 and err == ""
    assert "45624" in out and "SH degree 0" in out


def test_element_declared_twice(tmp_path):
    path = header_variant(tmp_path, b"end_header", b"element vertex 0\nend_header")
    expect_error(path, "element name twice")
