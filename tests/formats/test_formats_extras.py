"""A PLY's other per-splat properties (a ``label`` column, normals ``nx ny nz``) travel through
``convert`` and ``edit`` to a PLY, with the rows an edit keeps, merges or moves; a format that
cannot hold them says exactly which were dropped, and the round trip is never called bit-exact
when it is not (issue 38, item 5: a ``label`` column and ``nx = 1`` were dropped, the normals
zeroed, and 'round trip: bit-exact' printed)."""

from __future__ import annotations

import numpy as np
import numpy.lib.recfunctions as rfn

from helpers import random_scene
from splatgl.cli import main
from splatgl.formats import load_scene
from splatgl.formats.convert import conversion_error
from splatgl.formats.ply_write import scene_to_vertices, write_elements


def labelled(path, n=50, seed=0, degree=1, label_type=np.int32):
    """A PLY of ``n`` splats with ``nx = 1`` (ny, nz 0) and a ``label`` column (the row)."""
    rows = scene_to_vertices(random_scene(n, seed=seed, degree=degree))
    rows["nx"] = 1.0
    rows = rfn.append_fields(rows, "label", np.arange(n, dtype=label_type) + 1000 * seed,
                             usemask=False)
    write_elements(path, [("vertex", rows)])
    return rows


def cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_a_ply_keeps_its_other_properties_through_convert(tmp_path, capsys):
    rows = labelled(tmp_path / "in.ply")
    code, out, _ = cli(capsys, "convert", tmp_path / "in.ply", tmp_path / "out.ply")
    assert code == 0 and "round trip: bit-exact" in out and "dropped" not in out
    back = load_scene(tmp_path / "out.ply").extras
    assert back.dtype.names == ("nx", "ny", "nz", "label") and back["label"].dtype == np.int32
    assert np.array_equal(back["label"], rows["label"]) and (back["nx"] == 1).all()
    ascii = tmp_path / "a.ply"
    assert cli(capsys, "convert", tmp_path / "in.ply", ascii, "--sh-degree", "0")[0] == 0
    assert np.array_equal(load_scene(ascii).extras, load_scene(tmp_path / "in.ply").extras)


def test_a_format_without_them_names_exactly_what_was_dropped(tmp_path, capsys):
    labelled(tmp_path / "in.ply")
    code, out, _ = cli(capsys, "convert", tmp_path / "in.ply", tmp_path / "out.spz")
    assert code == 0 and "bit-exact" not in out
    assert "note: per-splat properties dropped: nx, ny, nz, label (the spz format cannot hold " \
           "them; .ply keeps them)" in out.splitlines()
    # normals that are all zero (every INRIA file's placeholders) are no loss worth a line
    plain = random_scene(20)
    from splatgl.formats import save_scene
    save_scene(tmp_path / "plain.ply", plain)
    code, out, _ = cli(capsys, "convert", tmp_path / "plain.ply", tmp_path / "plain.spz")
    assert code == 0 and "dropped" not in out


def test_bit_exact_counts_every_stored_value():
    a = random_scene(10)
    rows = rfn.append_fields(np.zeros(10, [("nx", "f4")]), "label", np.arange(10), usemask=False)
    import dataclasses
    with_label = dataclasses.replace(a, extras=rows)
    assert conversion_error(a, a)["bit_exact"]
    error = conversion_error(with_label, a)  # the label lost on the way
    assert not error["bit_exact"] and error["dropped"] == ["label"]
    changed = rows.copy()
    changed["label"][3] = 99
    assert not conversion_error(with_label, dataclasses.replace(a, extras=changed))["bit_exact"]


def test_edit_carries_them_with_the_rows_it_keeps_and_turns_the_normals(tmp_path, capsys):
    rows = labelled(tmp_path / "in.ply")
    out_path = tmp_path / "out.ply"
    code, out, _ = cli(capsys, "edit", tmp_path / "in.ply", "-o", out_path,
                       "--filter", "opacity >= 0.5", "--transform", '{"rotate_deg": [0, 0, 90]}')
    assert code == 0 and "dropped" not in out
    got = load_scene(out_path)
    keep = 1 / (1 + np.exp(-rows["opacity"].astype(np.float64))) >= 0.5
    assert 0 < got.count < 50 and np.array_equal(got.extras["label"], rows["label"][keep])
    assert np.allclose(got.extras["nx"], 0, atol=1e-6) and np.allclose(got.extras["ny"], 1)


def test_edit_merges_them_and_says_what_it_drops(tmp_path, capsys):
    labelled(tmp_path / "a.ply", n=30, seed=1)
    labelled(tmp_path / "b.ply", n=20, seed=2)
    code, out, _ = cli(capsys, "edit", tmp_path / "a.ply", tmp_path / "b.ply",
                       "-o", tmp_path / "m.ply", "--sh-degree", "0")
    assert code == 0 and "dropped" not in out
    label = load_scene(tmp_path / "m.ply").extras["label"]
    assert list(label) == list(range(1000, 1030)) + list(range(2000, 2020))
    note = "  note: per-splat properties dropped: nx, ny, nz, label"
    code, out, _ = cli(capsys, "edit", tmp_path / "a.ply", "-o", tmp_path / "d.ply",
                       "--decimate", "20")
    assert code == 0 and f"{note} (--decimate merges splats, whose own values they were)" in \
        out.splitlines(), out
    code, out, _ = cli(capsys, "edit", tmp_path / "a.ply", "-o", tmp_path / "s.sog",
                       "--sh-degree", "0")
    assert code == 0 and f"{note} (the sog format cannot hold them; .ply keeps them)" in \
        out.splitlines(), out


def test_dropped_invalid_rows_take_their_properties_with_them(tmp_path):
    import warnings

    rows = labelled(tmp_path / "in.ply", n=10)
    rows["x"][4] = np.nan
    write_elements(tmp_path / "bad.ply", [("vertex", rows)])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        got = load_scene(tmp_path / "bad.ply", drop_invalid=True)
    assert list(got.extras["label"]) == [0, 1, 2, 3, 5, 6, 7, 8, 9]
