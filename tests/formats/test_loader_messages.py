"""Loader error lines are safe to print, and loads that cannot fit in memory are refused first.

Issue 17 items 10-11: file content in a message is escaped and capped (:mod:`splatgl.formats.
_messages`); NumPy warnings never print on their own; every reader estimates the memory a load
needs from its header and refuses with one line naming both figures (:mod:`splatgl.formats.
_memory`) before allocating.
"""

from __future__ import annotations

import gzip
import os
import struct
import warnings

import numpy as np
import pytest

from splatgl.cli import main
from splatgl.errors import SceneFormatError
from splatgl.formats import _memory, load_scene
from splatgl.formats._messages import MESSAGE_LIMIT, QUOTE_LIMIT, clean_message, quote

from test_bad_input import good_vertices, write_vertices
from test_formats_compressed import _spz_body

MINIMAL_PROPS = ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1",
                 "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]


def run_info(capsys, path) -> tuple[int, str]:
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        rc = main(["info", str(path)])
    out, err = capsys.readouterr()
    return rc, err


def test_quote_escapes_and_caps():
    assert quote(b"ab\x1b[31mc\x00") == r"'ab\x1b[31mc\x00'"
    assert quote("tab\there") == r"'tab\x09here'"
    assert quote("bidi\u202eevil") == r"'bidi\u202eevil'"
    long = quote(b"\x00" * 3219)
    assert long == "'" + r"\x00" * QUOTE_LIMIT + "...' (3219 bytes)"
    assert quote("x" * (QUOTE_LIMIT + 1)).endswith(f"...' ({QUOTE_LIMIT + 1} characters)")
    assert clean_message("a\nb\x1b") == r"a\x0ab\x1b"
    assert len(clean_message("y" * 5000)) == MESSAGE_LIMIT


def ply_with_header_line(path, line: bytes) -> None:
    head = (b"ply\nformat binary_little_endian 1.0\nelement vertex 1\n" + line + b"\n"
            + b"".join(b"property float %s\n" % p.encode() for p in MINIMAL_PROPS)
            + b"end_header\n")
    path.write_bytes(head + np.zeros(len(MINIMAL_PROPS), "<f4").tobytes())


@pytest.mark.parametrize("line", [b"\x1b[2J\x1b[31mred", b"\x00" * 3219, b"property float \x1b]0;t\x07"])
def test_cli_error_line_escapes_file_bytes(tmp_path, capsys, line):
    path = tmp_path / "ansi.ply"
    ply_with_header_line(path, line)
    rc, err = run_info(capsys, path)
    assert rc == 2
    assert err.endswith("\n") and err[:-1].isprintable(), repr(err)
    assert "\x1b" not in err and "\x00" not in err and "Traceback" not in err
    assert len(err) < MESSAGE_LIMIT + 40


def test_property_name_with_escape_is_escaped_in_the_field(tmp_path, capsys):
    verts = good_vertices(4)
    path = write_vertices(tmp_path / "p.ply", verts)
    data = path.read_bytes().replace(b"property float rot_2", b"property float r\x1b[0m", 1)
    path.write_bytes(data)
    rc, err = run_info(capsys, path)
    assert rc == 2 and r"r\x1b[0m" in err and "\x1b" not in err and "'rot_2'" in err


def test_value_beyond_float32_names_the_field_and_prints_no_warning(tmp_path, capsys):
    verts = good_vertices(5)
    wide = np.empty(5, [(n, "<f8") for n in verts.dtype.names])
    for n in verts.dtype.names:
        wide[n] = verts[n]
    wide["y"][3] = 1e300  # overflows the cast to float32: NumPy would warn "overflow ... cast"
    path = write_vertices(tmp_path / "wide.ply", wide)
    rc, err = run_info(capsys, path)
    assert rc == 2 and len(err.splitlines()) == 1, err
    assert "field 'position'" in err and "first at index 3" in err and "warning" not in err


def test_spz_fractional_bits_31_is_one_line_at_once(tmp_path, capsys):
    body, _ = _spz_body(3, 7, 0, np.random.default_rng(0))
    path = tmp_path / "f31.spz"
    path.write_bytes(gzip.compress(body[:13] + bytes([31]) + body[14:]))
    rc, err = run_info(capsys, path)
    assert rc == 2 and len(err.splitlines()) == 1
    assert "field 'fractionalBits': 31 is outside 0-23" in err


# --- memory -----------------------------------------------------------------------------------


def test_sparse_ply_of_2_31_vertices_is_refused_before_allocating(tmp_path, monkeypatch):
    monkeypatch.setenv(_memory.ENV_AVAILABLE, str(64 << 30))  # the same figure on any machine
    n = 2 ** 31
    head = ("ply\nformat binary_little_endian 1.0\nelement vertex %d\n" % n
            + "".join(f"property float {p}\n" for p in MINIMAL_PROPS) + "end_header\n").encode()
    path = tmp_path / "huge.ply"
    with open(path, "wb") as fh:
        fh.write(head)
        fh.truncate(len(head) + n * 4 * len(MINIMAL_PROPS))  # sparse: no blocks written
    if os.stat(path).st_blocks * 512 > 1 << 20:
        pytest.skip("the temporary file system does not make sparse files")
    need = _memory.scene_bytes(n, 1) + n * _memory.ACTIVATE_BYTES + (1 << 16) * 56
    with pytest.raises(SceneFormatError) as info:
        load_scene(path)
    assert str(info.value) == (
        f"{path}: field 'vertex': 2147483648 splats need about {need / 1e9:.1f} GB of memory "
        f"to load, but only 68.7 GB is available (set {_memory.ENV_AVAILABLE}=BYTES to "
        "override)")


FIXTURES = {  # file -> the header field named
    "ply/donut_sh0.ply": "vertex",
    "fixtures/test64_sh3.compressed.ply": "vertex",
    "fixtures/minimal-v2.spz": "numPoints",
    "fixtures/minimal-raw.spz": "numPoints",
    "fixtures/minimal-v4.spz": "numPoints",
    "fixtures/minimal.ksplat": "splatCount",
    "fixtures/minimal.splat": None,
}


@pytest.mark.parametrize("name,field", FIXTURES.items())
def test_every_reader_checks_memory_from_its_header(shared_scenes, monkeypatch, name, field):
    path = shared_scenes / name
    scene = load_scene(path)
    k = scene.sh.shape[1]
    # room for the file but not for it and the scene's own arrays: every reader must refuse,
    # naming the splat count and the header field
    room = os.path.getsize(path) + _memory.scene_bytes(scene.count, k) - 1
    monkeypatch.setenv(_memory.ENV_AVAILABLE, str(room))
    with pytest.raises(SceneFormatError, match=f"{scene.count} splats need about") as info:
        load_scene(path)
    assert info.value.field == field
    # a file read whole is refused before reading when the file alone does not fit
    if not name.endswith(".ply") or "compressed" in name:
        monkeypatch.setenv(_memory.ENV_AVAILABLE, str(os.path.getsize(path) - 1))
        with pytest.raises(SceneFormatError, match="need"):
            load_scene(path)


def test_spz_gzip_claiming_more_than_deflate_can_hold(tmp_path):
    body, _ = _spz_body(2, 10, 0, np.random.default_rng(1))
    path = tmp_path / "big.spz"
    path.write_bytes(gzip.compress(body[:8] + struct.pack("<I", 10**9) + body[12:]))
    with pytest.raises(SceneFormatError, match="numPoints too large: 1000000000 points"):
        load_scene(path)
