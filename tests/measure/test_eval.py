"""`splatgl eval` on a synthetic dataset made here: the demo scene rendered through cameras
around it, the photographs perturbed by exactly +-DELTA per channel, so the expected PSNR is
-20 log10(DELTA) (the only other error is the 16-bit PNG quantisation of the photographs,
below 0.5/65535, which moves the PSNR by < 0.003 dB at DELTA = 0.04).
"""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest

from helpers import needs_framebuffer_fetch, summary_counts
from splatgl.cameras.camera import Camera
from splatgl.cameras.poses import orbit
from splatgl.cli import main
from splatgl.commands._common import demo_scene_path
from splatgl.datasets import colmap, nerf
from splatgl.datasets.dataset import Split, load_dataset, split_views
from splatgl.datasets.named_camera import NamedCamera
from splatgl.errors import SplatglError
from splatgl.formats import load_scene
from splatgl.imagefiles.images import read_image, write_image
from splatgl.measure.evaluation.metrics import ssim
from splatgl.scene.settings import RenderSettings

DELTA = 0.04
EXPECTED_PSNR = -20.0 * math.log10(DELTA)  # 27.959 dB
BG = (0.5, 0.5, 0.5)
W, H, N_VIEWS = 64, 48, 9


def _perturb(render: np.ndarray) -> np.ndarray:
    """``render`` (clamped) moved by exactly DELTA per channel, away from the nearer bound."""
    base = np.clip(render[..., :3], 0.0, 1.0)
    return base + np.where(base < 0.5, DELTA, -DELTA)


def _write_rgba(path, rgba):
    """A 16-bit RGBA PNG (splatgl's write_image writes RGB only)."""
    import OpenImageIO as oiio

    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), oiio.ImageSpec(rgba.shape[1], rgba.shape[0], 4, oiio.UINT16))
    assert out.write_image(np.round(np.clip(rgba, 0, 1) * 65535).astype(np.uint16))
    out.close()


@pytest.fixture(scope="module")
def dataset(tmp_path_factory, gl_renderer):
    """A COLMAP + transforms.json dataset of the demo scene: images/ at 64x48, images_2/ at
    32x24, and rgba/ with alpha 0 (and garbage colour) wherever the render is pure background."""
    root = tmp_path_factory.mktemp("synthetic")
    scene = load_scene(demo_scene_path())
    settings = RenderSettings(background=BG)
    lo, hi = scene.robust_bounds
    views = []
    for i in range(N_VIEWS):
        cam = Camera.from_fov(W, H, 45.0, orbit(0.5 * (lo + hi), 6.0, 40.0 * i, 15.0))
        name = f"img_{i:02d}.png"
        rgba = gl_renderer.render(scene, cam, settings)
        for folder, c in (("images", cam), ("images_2", cam.resized(W // 2, H // 2))):
            img = rgba if c is cam else gl_renderer.render(scene, c, settings)
            photo = _perturb(img)
            (root / folder).mkdir(exist_ok=True)
            write_image(root / folder / name, np.concatenate([photo, np.ones_like(photo[..., :1])], -1), 16)
        empty = rgba[..., 3] == 0.0
        photo = np.where(empty[..., None], [1.0, 0.0, 0.0], _perturb(rgba))  # red where masked out
        (root / "rgba").mkdir(exist_ok=True)
        _write_rgba(root / "rgba" / name, np.concatenate([photo, (~empty)[..., None]], -1))
        views.append(NamedCamera(name, cam))
    colmap.write_colmap(root / "sparse" / "0", views)
    tj = nerf.transforms_json([NamedCamera(f"images/{v.name}", v.camera) for v in views])
    (root / "nerf").mkdir()
    (root / "nerf" / "images").symlink_to(root / "images")
    (root / "nerf" / "images_2").symlink_to(root / "images_2")
    (root / "nerf" / "transforms.json").write_text(json.dumps(tj))
    return root


def _run(capsys, *argv):
    code = main(["eval", str(demo_scene_path()), "--background", "0.5,0.5,0.5", *map(str, argv)])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_colmap_dataset_psnr_is_the_known_perturbation(dataset, capsys, tmp_path):
    code, out, err = _run(capsys, "--dataset", dataset, "--csv", tmp_path / "s.csv", "--json", tmp_path / "s.json")
    assert code == 0, err
    rows = list(csv.reader((tmp_path / "s.csv").open()))
    assert rows[0] == ["view", "psnr", "ssim"] and len(rows) == N_VIEWS + 2
    psnrs = [float(r[1]) for r in rows[1:-1]]
    assert np.allclose(psnrs, EXPECTED_PSNR, atol=0.01), psnrs
    assert rows[-1][0] == "mean" and float(rows[-1][1]) == pytest.approx(np.mean(psnrs))
    report = json.loads((tmp_path / "s.json").read_text())
    assert [v["name"] for v in report["views"]] == [f"img_{i:02d}.png" for i in range(N_VIEWS)]
    assert report["mean"]["psnr"] == pytest.approx(EXPECTED_PSNR, abs=0.01)
    assert 0.8 < report["mean"]["ssim"] < 1.0
    assert f"mean ({N_VIEWS} views)" in out and "27.959" in out


def test_transforms_json_dataset_matches_colmap(dataset, capsys, tmp_path):
    code, _, err = _run(capsys, "--dataset", dataset / "nerf", "--json", tmp_path / "n.json")
    assert code == 0, err
    report = json.loads((tmp_path / "n.json").read_text())
    assert [v["psnr"] for v in report["views"]] == pytest.approx([EXPECTED_PSNR] * N_VIEWS, abs=0.01)


def test_split_every_eighth_and_downscaled_folder(dataset, capsys, tmp_path):
    views = load_dataset(dataset, split="test")
    assert [v.name for v in views] == ["img_00.png", "img_08.png"]
    assert [v.name for v in load_dataset(dataset, split="train")] == [f"img_{i:02d}.png" for i in range(1, 8)]
    half = load_dataset(dataset, images="images_2", split=Split.TEST)
    assert (half[0].camera.width, half[0].camera.height) == (W // 2, H // 2)
    assert half[0].camera.fx == pytest.approx(views[0].camera.fx / 2)
    code, out, err = _run(capsys, "--dataset", dataset / "nerf", "--images", "images_2", "--split", "test",
                          "--json", tmp_path / "h.json")
    assert code == 0, err
    report = json.loads((tmp_path / "h.json").read_text())
    assert [v["name"] for v in report["views"]] == ["images/img_00.png", "images/img_08.png"]
    assert report["mean"]["psnr"] == pytest.approx(EXPECTED_PSNR, abs=0.01)


def test_rgba_photographs_composite_over_the_background(dataset, capsys, tmp_path, gl_renderer):
    code, _, err = _run(capsys, "--dataset", dataset, "--images", "rgba", "--select", "0:3",
                        "--json", tmp_path / "a.json")
    assert code == 0, err
    got = [v["psnr"] for v in json.loads((tmp_path / "a.json").read_text())["views"]]
    # Error DELTA on the drawn pixels, 0 where the photograph is masked out (composited to the
    # background, which the render shows there exactly).
    for i, value in enumerate(got):
        drawn = read_image(dataset / "rgba" / f"img_{i:02d}.png")[..., 3] > 0.5
        assert 0.1 < drawn.mean() < 0.95  # the mask really removes something
        assert value == pytest.approx(-10 * math.log10(DELTA ** 2 * drawn.mean()), abs=0.01)


def test_a_photographs_partial_alpha_is_applied_once(tmp_path):
    """A PNG stores straight alpha: colour c at alpha a over background b is c a + b (1 - a).
    OpenImageIO hands such a file's colour multiplied by a unless told otherwise, and eval
    multiplied it again (a Blender-style dataset of splatgl's own renders scored 46.5 dB, its
    RGB twin 70 dB)."""
    import OpenImageIO as oiio

    from splatgl.measure.evaluation.evaluate import load_photo

    c, a, b = np.float32(0.8), np.float32(0.25), np.float32(0.5)
    stored = np.tile(np.array([c, c, c, a], np.float32), (4, 4, 1))
    path = tmp_path / "p.png"
    spec = oiio.ImageSpec(4, 4, 4, oiio.UINT16)
    spec.attribute("oiio:UnassociatedAlpha", 1)          # write the values as they are
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec) and out.write_image(np.round(stored * 65535).astype(np.uint16))
    out.close()
    # atol: 16-bit storage rounds each value by at most 0.5 / 65535 = 7.6e-6 (1e-4 is ample;
    # alpha applied twice would be off by 0.15 here)
    np.testing.assert_allclose(read_image(path), stored, atol=1e-4)   # as stored
    np.testing.assert_allclose(load_photo(path, 4, 4, (b, b, b)), c * a + b * (1 - a), atol=1e-4)


def test_the_table_columns_line_up_with_short_view_names():
    from splatgl.measure.evaluation.evaluate import Evaluation, ViewScore

    table = Evaluation((ViewScore("a", 30.0, 0.9), ViewScore("b", 32.0, 0.95))).table()
    lines = table.splitlines()
    assert lines[-1].startswith("mean (2 views)")
    assert len({len(line) for line in lines}) == 1, table   # the columns end alike


def test_sheet_of_worst_views(dataset, capsys, tmp_path):
    code, _, err = _run(capsys, "--dataset", dataset, "--split", "test", "--sheet", tmp_path / "w.png", "--worst", "2")
    assert code == 0, err
    sheet = read_image(tmp_path / "w.png")
    # two rows of render | photograph (2W + 4) | heat map (W), each row H + 4 high
    assert sheet.shape[:2] == (2 * (H + 4), 3 * W + 8)


def test_ssim_equals_scikit_image(dataset):
    metrics = pytest.importorskip("skimage.metrics")
    a = read_image(dataset / "images" / "img_01.png")[..., :3]
    rng = np.random.default_rng(3)
    b = np.clip(a + rng.normal(0.0, 0.05, a.shape), 0, 1).astype(np.float32)
    ref = metrics.structural_similarity(a, b, gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
                                        data_range=1.0, channel_axis=-1)
    assert ssim(a, b) == pytest.approx(ref, abs=1e-6)
    assert 0.3 < ref < 0.95


@pytest.mark.parametrize("args, message", [
    (["--dataset", "nowhere"], "nowhere: no such dataset folder"),
    (["--dataset", "{root}", "--images", "images_8"], "images_8: no such image folder beside the COLMAP model"),
    (["--dataset", "{root}", "--select", "20"], "--select index 20 out of range (9 cameras)"),
    (["--dataset", "{root}", "--worst", "0"], "--worst must be at least 1, got 0"),
])
def test_bad_eval_input_is_one_line(dataset, capsys, args, message):
    code, _, err = _run(capsys, *[a.replace("{root}", str(dataset)) for a in args])
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1, err


def test_missing_photograph_named(dataset, tmp_path, capsys):
    views = [NamedCamera("a.png", Camera.from_fov(W, H, 45.0, orbit([0, 0, 0], 5.0, 0.0, 0.0)))]
    colmap.write_colmap(tmp_path / "sparse" / "0", views, binary=False)
    (tmp_path / "images").mkdir()
    code, _, err = _run(capsys, "--dataset", tmp_path)
    assert code == 2 and "a.png: photograph of COLMAP image 'a.png' not found" in err


def test_photograph_of_another_aspect_is_refused(tmp_path, capsys):
    """A 64x64 photograph for a 64x48 camera was stretched into without a word."""
    views = [NamedCamera("a.png", Camera.from_fov(W, H, 45.0, orbit([0, 0, 0], 5.0, 0.0, 0.0)))]
    colmap.write_colmap(tmp_path / "sparse" / "0", views, binary=False)
    (tmp_path / "images").mkdir()
    write_image(tmp_path / "images" / "a.png", np.zeros((64, 64, 4), np.float32))
    code, out, err = _run(capsys, "--dataset", tmp_path)
    assert (code, out) == (2, "")
    assert err == (f"splatgl: error: {tmp_path / 'images' / 'a.png'}: photograph 64x64 has another "
                   "aspect than its camera's 64x48 (1 against 1.333); the render would be "
                   "stretched to it\n")
    write_image(tmp_path / "images" / "a.png", np.zeros((25, 33, 4), np.float32))  # 1/2, rounded
    assert [(v.camera.width, v.camera.height) for v in load_dataset(tmp_path)] == [(33, 25)]


def test_images_smaller_than_the_ssim_window_are_refused(tmp_path, capsys):
    """SSIM of an image under 11x11 has no valid region: it returned a number all the same."""
    a = np.zeros((10, 12, 3), np.float32)
    with pytest.raises(SplatglError, match=r"^image 12x10 is smaller than SSIM's 11x11 window; "
                                           r"SSIM needs at least 11 pixels a side$"):
        ssim(a, a)
    assert ssim(np.zeros((11, 11, 3)), np.zeros((11, 11, 3))) == 1.0
    views = [NamedCamera("a.png", Camera.from_fov(16, 8, 45.0, orbit([0, 0, 0], 5.0, 0.0, 0.0)))]
    colmap.write_colmap(tmp_path / "sparse" / "0", views, binary=False)
    (tmp_path / "images").mkdir()
    write_image(tmp_path / "images" / "a.png", np.zeros((8, 16, 4), np.float32))
    code, out, err = _run(capsys, "--dataset", tmp_path)
    assert (code, err) == (2, f"splatgl: error: {tmp_path / 'images' / 'a.png'}: evaluated at 16x8 "
                              "is smaller than SSIM's 11x11 window; SSIM needs at least 11 pixels "
                              "a side\n")
    rc = main(["compare", "--width", "10", "--height", "20"])
    assert (rc, capsys.readouterr().err) == (2, "splatgl: error: --width/--height: image 10x20 is "
                                                "smaller than SSIM's 11x11 window; SSIM needs at "
                                                "least 11 pixels a side\n")


def test_json_dash_prints_the_report_alone(dataset, capsys, tmp_path):
    code, out, err = _run(capsys, "--dataset", dataset, "--select", "0:2", "--json", "-",
                          "--csv", tmp_path / "s.csv")
    assert code == 0, err
    assert [v["name"] for v in json.loads(out)["views"]] == ["img_00.png", "img_01.png"]
    assert f"wrote {tmp_path / 's.csv'}" in err


def test_split_views_is_every_eighth():
    views = [NamedCamera(str(i), Camera.from_fov(8, 8, 40.0)) for i in range(20)]
    assert [v.name for v in split_views(views, Split.TEST)] == ["0", "8", "16"]
    assert len(split_views(views, Split.TRAIN)) == 17


@pytest.mark.slow
def test_two_workers_give_the_single_process_report(dataset, capsys, tmp_path, monkeypatch):
    """The views split over 2 processes: CSV, JSON and the worst-views sheet byte-identical to
    one process's; one progress line counts both workers' views; the summary's per-worker views
    add up to the total."""
    monkeypatch.setenv("SPLATGL_PROGRESS", "1")
    files = {}
    for n in (1, 2):
        code, out, err = _run(capsys, "--dataset", dataset, "--workers", n, "--csv", tmp_path / f"{n}.csv",
                              "--json", tmp_path / f"{n}.json", "--sheet", tmp_path / f"{n}.png", "--worst", "3")
        assert code == 0, err
        files[n] = [(tmp_path / f"{n}.{ext}").read_bytes() for ext in ("csv", "json", "png")]
        table = out.split("\nw")[0]   # up to the summary or the "wrote" lines
        if n == 1:
            one_table = table
            assert "worker " not in out
    assert files[2] == files[1] and table == one_table
    assert err.count(f"100.0% ({N_VIEWS} / {N_VIEWS})") == 1 and "views/s, ETA" in err, err
    workers, total = summary_counts(out, "views")
    assert 1 <= len(workers) <= 2 and sum(workers) == total == N_VIEWS   # one may take both


@pytest.mark.parametrize("reports, message", [
    (["--csv", "{t}/nodir/x.csv"], "--csv {t}/nodir/x.csv: folder {t}/nodir does not exist"),
    (["--csv", "{t}/e.json", "--json", "{t}/e.json"],
     "--json {t}/e.json: the same file as --csv; give the report its own name"),
    (["--sheet", "{t}/w.bmp"],
     "--sheet {t}/w.bmp: unsupported image format ('.bmp'); use .png, .tif, .tiff or .exr"),
])
def test_report_paths_are_checked_before_scoring(dataset, tmp_path, capsys, monkeypatch, reports, message):
    """A report that cannot be written failed only after every view was scored (and the same
    file as --csv and --json was accepted)."""
    import splatgl.commands.eval as command

    monkeypatch.setattr(command, "evaluate", lambda *a, **k: pytest.fail("scored before checking"))
    code, out, err = _run(capsys, "--dataset", dataset, *[a.replace("{t}", str(tmp_path)) for a in reports])
    assert (code, err) == (2, f"splatgl: error: {message.replace('{t}', str(tmp_path))}\n")
    assert list(tmp_path.iterdir()) == []


def test_reports_are_written_all_or_none(dataset, tmp_path, capsys, monkeypatch):
    import splatgl.commands.eval as command

    def failing(path, text):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(command, "atomic_write_text", lambda p, t: failing(p, t) if p.suffix == ".json"
                        else (p.write_text(t)))
    code, _, err = _run(capsys, "--dataset", dataset, "--csv", tmp_path / "e.csv", "--json", tmp_path / "e.json")
    assert code == 2 and err.startswith(f"splatgl: error: {tmp_path / 'e.json'}: cannot write (No space"), err
    assert list(tmp_path.iterdir()) == []  # not the CSV alone


def test_renders_carry_the_layers_of_every_view(dataset, capsys, tmp_path, gl_renderer):
    """--renders DIR --format exr --layers ...: one EXR per view with those channels, whose
    colour is the render scored (the scores are unchanged)."""
    needs_framebuffer_fetch(gl_renderer.ctx)
    import OpenImageIO as oiio
    from splatgl.imagefiles.images import read_image

    out = tmp_path / "renders"
    code, text, err = _run(capsys, "--dataset", dataset, "--renders", out, "--format", "exr",
                           "--layers", "depth,normal,count,top-id", "--json", tmp_path / "s.json")
    assert code == 0, err
    report = json.loads((tmp_path / "s.json").read_text())
    assert report["mean"]["psnr"] == pytest.approx(EXPECTED_PSNR, abs=0.01)
    files = sorted(p.name for p in out.iterdir())
    assert files == [f"img_{i:02d}.exr" for i in range(N_VIEWS)]
    spec = oiio.ImageInput.open(str(out / "img_00.exr")).spec()
    assert set(spec.channelnames) == {"R", "G", "B", "A", "Z", "N.X", "N.Y", "N.Z", "count", "id"}
    assert f"wrote {N_VIEWS} renders to {out}" in text
    views = load_dataset(dataset, None, "all", 1600)
    settings = RenderSettings(background=(0.5, 0.5, 0.5))
    expected = gl_renderer.render(load_scene(demo_scene_path()), views[0].camera, settings)
    px = read_image(out / "img_00.exr")
    names = list(spec.channelnames)
    got = px[..., [names.index(c) for c in "RGBA"]]
    np.testing.assert_array_equal(got, expected)
    # pictures beside PNG renders; options that describe renders need --renders
    code, _, err = _run(capsys, "--dataset", dataset, "--renders", tmp_path / "p", "--layers", "count")
    assert code == 0, err
    assert (tmp_path / "p" / "img_00_count.png").is_file()
    code, _, err = _run(capsys, "--dataset", dataset, "--layers", "count")
    assert code == 2 and "--layers describe the renders eval writes; give --renders DIR" in err
