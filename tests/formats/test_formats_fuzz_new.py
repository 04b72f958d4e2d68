"""Truncated and corrupted SOG (bundle and folder), glTF / GLB, and splatgl-written SPZ v2/v3,
compressed PLY, PLY and .splat files: load or SceneFormatError in bounded memory (same rules
as test_formats_fuzz.py).  A truncated file must fail, but for .splat, which has no header:
cut at a whole record it is the written scene's first rows.

Beside byte-level damage, the JSON of SOG's meta.json and of glTF gets structural damage: keys
removed, values replaced by other JSON types or by out-of-range numbers.
"""

from __future__ import annotations

import copy
import json
import warnings
import zipfile

import numpy as np
import pytest

from splatgl.formats import gltf, load_scene, save_scene, sog

from helpers import check_case, corruptions, random_scene, truncations

#: Replacement values for JSON damage: wrong types, huge and negative numbers.
ODD_VALUES = [None, "x", -1, 0, 1e308, 2 ** 40, [], {}, [1, "a"], True, [[1, 2], [3]], 3.5]


def json_damage(obj, rng, cases: int) -> list:
    """Copies of ``obj`` with one key removed or one value replaced, at random depths."""
    paths = []

    def walk(node, path):
        if isinstance(node, dict):
            for k, v in node.items():
                paths.append(path + [k])
                walk(v, path + [k])
        elif isinstance(node, list):
            for i, v in enumerate(node[:4]):
                paths.append(path + [i])
                walk(v, path + [i])

    walk(obj, [])
    out = []
    for pick in rng.choice(len(paths), min(cases, len(paths)), replace=False):
        damaged = copy.deepcopy(obj)
        parent = damaged
        *head, last = paths[pick]
        for key in head:
            parent = parent[key]
        if isinstance(parent, dict) and rng.random() < 0.3:
            del parent[last]
        else:
            parent[last] = ODD_VALUES[int(rng.integers(len(ODD_VALUES)))]
        out.append(damaged)
    return out


def assert_same_scene(got, want) -> None:
    assert got.kind is want.kind and got.count == want.count
    for name in ("means", "quats", "log_scales", "opacity_logits", "sh"):
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name), err_msg=name)


@pytest.fixture(scope="module")
def scenes():
    return {"sh0": random_scene(300, degree=0, seed=3), "sh2": random_scene(300, degree=2, seed=4)}


@pytest.mark.parametrize("degree", ["sh0", "sh2"])
@pytest.mark.parametrize("suffix", [".sog", ".glb", ".gltf", ".spz", ".compressed.ply", ".ply",
                                    ".splat"])
def test_damaged_written_files(tmp_path, scenes, degree, suffix):
    src = tmp_path / ("src" + suffix)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # .splat drops SH degree 2 with a warning
        save_scene(src, scenes[degree], **({"version": 2} if suffix == ".spz" and degree == "sh0"
                                            else {}))
    whole = load_scene(src)
    data = src.read_bytes()
    rng = np.random.default_rng(len(data))
    path = tmp_path / ("damaged" + suffix)
    lengths = truncations(len(data), 12, rng)
    if suffix == ".splat":  # 32-byte records, no header: a cut at a record is a shorter scene
        lengths += [32, len(data) // 2 // 32 * 32, len(data) - 32]
    for length in lengths:
        record = suffix == ".splat" and length > 0 and length % 32 == 0
        got = check_case(load_scene, path, data[:length], f"{suffix} cut to {length} bytes",
                         must_fail=not record)
        if record:
            assert_same_scene(got, whole.subset(np.arange(length // 32)))
    for i, damaged in enumerate(corruptions(data, 12, rng)):
        check_case(load_scene, path, damaged, f"{suffix} corruption {i}")


def test_damaged_sog_meta_and_textures(tmp_path, scenes):
    src = tmp_path / "src.sog"
    save_scene(src, scenes["sh2"])
    with zipfile.ZipFile(src) as zf:
        entries = {name: zf.read(name) for name in zf.namelist()}
    meta = json.loads(entries["meta.json"])
    rng = np.random.default_rng(7)
    path = tmp_path / "damaged.sog"

    def bundle(replace: dict) -> bytes:
        with zipfile.ZipFile(path, "w") as zf:
            for name, blob in {**entries, **replace}.items():
                zf.writestr(name, blob)
        return path.read_bytes()

    for i, damaged in enumerate(json_damage(meta, rng, 40)):
        check_case(sog.read, path, bundle({"meta.json": json.dumps(damaged)}), f"meta damage {i}")
    for name in [n for n in entries if n.endswith(".webp")]:
        blob = entries[name]
        for length in (0, 12, len(blob) // 2):
            check_case(sog.read, path, bundle({name: blob[:length]}), f"{name} cut to {length}",
                       must_fail=True)
    # the folder form: meta.json beside damaged textures
    folder = tmp_path / "folder"
    folder.mkdir()
    for name, blob in entries.items():
        (folder / name).write_bytes(blob)
    (folder / "means_u.webp").write_bytes(entries["means_u.webp"][:40])
    check_case(sog.read, folder / "meta.json", entries["meta.json"], "folder, cut texture",
               must_fail=True)
    (folder / "means_u.webp").unlink()
    check_case(sog.read, folder / "meta.json", entries["meta.json"], "folder, missing texture",
               must_fail=True)


def test_damaged_gltf_json(tmp_path, scenes):
    src = tmp_path / "src.gltf"
    save_scene(src, scenes["sh2"])
    doc = json.loads(src.read_text())
    rng = np.random.default_rng(11)
    path = tmp_path / "damaged.gltf"
    for i, damaged in enumerate(json_damage(doc, rng, 60)):
        check_case(gltf.read, path, json.dumps(damaged).encode(), f"glTF JSON damage {i}")
