"""The conformance kit: exported, rendered by splatgl's quad and tile paths (passing), and by
deliberately wrong renderers (y-flipped, 16-bit sorted) failing with the right explanation."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from splatgl.api import Renderer
from splatgl.cli import main
from splatgl.measure.conformance.cases import demo_cases, depth_range_case, stress_cases
from splatgl.measure.conformance.export import export_kit
from splatgl.measure.conformance.score import case_inputs, load_index, render_kit, score_kit
from splatgl.errors import SplatglError
from splatgl.formats import load_scene
from splatgl.imagefiles.images import read_image, write_image
from splatgl.commands._common import demo_scene_path


@pytest.fixture(scope="module")
def kit(tmp_path_factory):
    demo = load_scene(demo_scene_path())
    cases = [depth_range_case()] + demo_cases(demo)[:3] + [
        c for c in stress_cases() if c.name in ("stress_aniso_45", "stress_surfels_edge_on")]
    out = tmp_path_factory.mktemp("kit") / "kit"
    export_kit(out, cases)
    return out


def test_kit_layout(kit):
    index = load_index(kit)
    names = [c["name"] for c in index["cases"]]
    assert names[0] == "depth_range" and "demo_fisheye" in names and "stress_surfels_edge_on" in names
    entry = index["cases"][0]
    for key in ("scene", "camera", "reference_exr", "reference_png"):
        assert (kit / entry[key]).is_file()
    assert entry["tolerance"] == {"min_psnr": 40.0, "max_off_4": 0.01} and entry["near"] > 0
    ref = read_image(kit / entry["reference_exr"])
    assert ref.shape == (entry["height"], entry["width"], 5)      # R, G, B, A, Z
    readme = (kit / "README.md").read_text()
    for word in ("pixel centres", "y direction", "sh layout", "alpha", "early stop"):
        assert word in readme.lower()
    assert set(index["conventions"]) >= {"pixel_centres", "y_direction", "sh_layout", "early_stop"}


@pytest.mark.parametrize("kind", ["quad", "tile"])
def test_splatgl_renderers_pass(kit, tmp_path, kind):
    skipped = render_kit(kit, tmp_path, kind)
    assert skipped == []
    scores = score_kit(kit, tmp_path)
    assert [s.status for s in scores] == ["pass"] * len(scores), scores
    assert main(["conformance", "score", str(kit), "--images", str(tmp_path), "--no-explain"]) == 0


def test_cpu_renderer_passes_what_it_draws(kit, tmp_path):
    """The CPU renderer draws every 3DGS case (perspective, orthographic, fisheye) and skips
    the surfel case with its one-line reason."""
    pytest.importorskip("numba", reason="the CPU renderer needs numba (the fast extra)")
    skipped = render_kit(kit, tmp_path, "cpu")
    assert len(skipped) == 1 and skipped[0].startswith("stress_surfels_edge_on: "), skipped
    scores = [s for s in score_kit(kit, tmp_path) if s.status != "missing"]
    assert len(scores) == 5 and all(s.status == "pass" for s in scores), scores


def test_a_y_flipped_renderer_fails_as_upside_down(kit, tmp_path):
    render_kit(kit, tmp_path / "q", "quad")
    (tmp_path / "f").mkdir()
    for p in (tmp_path / "q").glob("*.exr"):
        write_image(tmp_path / "f" / p.name, np.ascontiguousarray(read_image(p)[::-1, :, :4]))
    scores = {s.name: s for s in score_kit(kit, tmp_path / "f")}
    assert scores["depth_range"].status == "fail"
    assert scores["depth_range"].explanation.startswith("looks upside down")
    assert scores["demo_perspective"].explanation.startswith("looks upside down")
    # a failed case fails the run (exit 1), so CI can gate on it
    assert main(["conformance", "score", str(kit), "--images", str(tmp_path / "f"), "--no-explain"]) == 1


def test_a_16_bit_sorted_renderer_fails_explained_by_sort_bucket16(kit, tmp_path):
    with Renderer() as r:
        for e in load_index(kit)["cases"]:
            scene, cam, settings = case_inputs(kit, e)
            settings = dataclasses.replace(settings, sort_key="bucket16")
            write_image(tmp_path / f"{e['name']}.png", r.render(scene, cam, settings, "quad"))
    scores = {s.name: s for s in score_kit(kit, tmp_path)}
    assert scores["depth_range"].status == "fail"
    assert scores["depth_range"].explanation.startswith("sort=bucket16 (+")
    assert scores["demo_perspective"].status == "pass"


def test_cli_score_json_missing_and_bad_kit(kit, tmp_path, capsys):
    (tmp_path / "none").mkdir()
    out = tmp_path / "s.json"
    assert main(["conformance", "score", str(kit), "--images", str(tmp_path / "none"),
                 "--json", str(out)]) == 1                  # missing images fail the run
    report = json.loads(out.read_text())
    assert report["passed"] == 0 and {c["status"] for c in report["cases"]} == {"missing"}
    capsys.readouterr()
    assert main(["conformance", "score", str(tmp_path), "--images", str(tmp_path / "none")]) == 2
    assert "not a conformance kit (no index.json" in capsys.readouterr().err
    assert main(["conformance", "export", str(kit)]) == 2
    assert "exists (use --force to replace it)" in capsys.readouterr().err
    with pytest.raises(SplatglError, match="no such folder"):
        score_kit(kit, tmp_path / "nowhere")


def test_index_with_a_repeated_key_is_refused(tmp_path):
    """Issue 38: a repeated key silently took the last value (here a case's "name")."""
    (tmp_path / "index.json").write_text('{"version": 1, "version": 2, "cases": []}')
    with pytest.raises(SplatglError) as info:
        load_index(tmp_path)
    assert str(info.value) == (f"{tmp_path / 'index.json'}: key 'version' given twice in one "
                               "object (JSON keeps only the last)")
