"""``--layers`` through the command line: an EXR with a named channel per layer, PNG pictures
with their scales, every frame of ``--path``, and one-line refusals."""

from __future__ import annotations

import numpy as np
import OpenImageIO as oiio
import pytest

from splatgl.api import default_camera
from splatgl.cli import main
from splatgl.commands._common import demo_scene_path
from splatgl.formats import load_scene
from helpers import needs_framebuffer_fetch
from splatgl.scene.settings import RenderSettings
from splatgl.imagefiles.images import read_image
from splatgl.output.layers import Layer, with_layers

ARGS = ["--width", "96", "--height", "64"]
ALL = "colour,alpha,depth,median-depth,normal,count,top-id"


def _channels(path):
    inp = oiio.ImageInput.open(str(path))
    spec = inp.spec()
    px = np.asarray(inp.read_image(oiio.FLOAT), np.float32)
    inp.close()
    return {name: px[..., k] for k, name in enumerate(spec.channelnames)}, spec


def test_exr_holds_a_named_channel_per_layer(tmp_path, gl_renderer):
    needs_framebuffer_fetch(gl_renderer.ctx)
    out = tmp_path / "v.exr"
    assert main(["render", "-o", str(out), "--layers", ALL, "--normal-space", "world"] + ARGS) == 0
    ch, spec = _channels(out)
    assert set(ch) == {"R", "G", "B", "A", "Z", "median.Z", "N.X", "N.Y", "N.Z", "count", "id"}
    assert spec.getattribute("splatgl:depth") == "z" and spec.getattribute("splatgl:normal") == "world"
    scene = load_scene(demo_scene_path())
    camera = default_camera(scene, 96, 64)
    api = gl_renderer.render_layers(scene, camera, RenderSettings(), layers=with_layers(*Layer))
    np.testing.assert_array_equal(ch["count"], api.count)
    np.testing.assert_array_equal(ch["id"], api.top_id)
    np.testing.assert_array_equal(ch["median.Z"], api.median_depth)
    n = np.stack([ch["N.X"], ch["N.Y"], ch["N.Z"]], -1)
    np.testing.assert_allclose(n, api.unit_normals(camera.world_to_camera), atol=1e-6)
    drawn = api.alpha > 0.5
    np.testing.assert_allclose(np.linalg.norm(n[drawn], axis=-1), 1.0, atol=1e-5)
    assert (ch["id"][api.alpha == 0] == -1).all()


def test_exr_without_layers_is_unchanged(tmp_path):
    out = tmp_path / "v.exr"
    assert main(["render", "-o", str(out)] + ARGS) == 0
    ch, _ = _channels(out)
    assert list(ch) == ["R", "G", "B", "A", "Z"]
    assert main(["render", "-o", str(out), "--layers", "normal", "--force"] + ARGS) == 0
    ch, _ = _channels(out)
    assert set(ch) == {"R", "G", "B", "A", "N.X", "N.Y", "N.Z"}


def test_png_gets_a_picture_per_layer_with_its_scale(tmp_path, capsys):
    out = tmp_path / "v.png"
    assert main(["render", "-o", str(out), "--layers", ALL, "--renderer", "tile"] + ARGS) == 0
    text = capsys.readouterr().out
    for layer in ("alpha", "depth", "median-depth", "normal", "count", "top-id"):
        picture = tmp_path / f"v_{layer}.png"
        img = read_image(picture)
        assert img.shape[1] == 96 and img.shape[0] > 64, layer   # a scale or caption below
        assert f"wrote {picture} ({layer})" in text
    assert read_image(out).shape == (64, 96, 3)
    assert not (tmp_path / "v_colour.png").exists()


def test_every_frame_of_a_path_carries_the_layers(tmp_path, capsys, gl_renderer):
    needs_framebuffer_fetch(gl_renderer.ctx)
    assert main(["render", "--path", "orbit:2", "-o", str(tmp_path / "f/%03d.exr"),
                 "--layers", "depth,count"] + ARGS) == 0
    for k in range(2):
        ch, _ = _channels(tmp_path / f"f/{k:03d}.exr")
        assert set(ch) == {"R", "G", "B", "A", "Z", "count"} and ch["count"].max() > 1
    assert main(["render", "--path", "orbit:2", "-o", str(tmp_path / "p/"), "--layers", "normal"]
                + ARGS) == 0
    assert (tmp_path / "p" / "00001_normal.png").is_file()
    # --resume: a frame missing one of its pictures is rendered again
    (tmp_path / "p" / "00001_normal.png").unlink()
    capsys.readouterr()
    assert main(["render", "--path", "orbit:2", "-o", str(tmp_path / "p/"), "--layers", "normal",
                 "--resume"] + ARGS) == 0
    assert "wrote 1 frames" in capsys.readouterr().out
    assert (tmp_path / "p" / "00001_normal.png").is_file()


@pytest.mark.parametrize("args, message", [
    (["-o", "v.png", "--layers", "colour,nromal"], "--layers: unknown layer 'nromal'"),
    (["-o", "v.png", "--normal-space", "world"], "--normal-space world applies to the normal layer"),
    (["-o", "v.mp4", "--path", "orbit:2", "--layers", "depth"], "a video holds the colour alone"),
    (["-o", "v.png", "--under-depth", "z"], "--under-depth describes the --under file"),
    (["-o", "v.png", "--under", "nothing.exr"], "--under nothing.exr: no such file"),
])
def test_layer_options_refused_in_one_line(tmp_path, capsys, monkeypatch, args, message):
    monkeypatch.chdir(tmp_path)
    code = main(["render"] + args + ARGS)
    err = capsys.readouterr().err
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1


def test_top_id_into_exr_is_refused_past_float32_integers():
    from splatgl.errors import SplatglError
    from splatgl.imagefiles.layer_files import EXACT_FLOAT_IDS, LayerFiles, check_exact_ids

    files = LayerFiles((Layer.TOP_ID,))
    check_exact_ids(files, "v.exr", EXACT_FLOAT_IDS)          # 2^24: still exact
    check_exact_ids(files, "v.png", EXACT_FLOAT_IDS + 1)      # a picture: no ids in the file
    with pytest.raises(SplatglError, match="v.exr: the EXR id channel is float32, exact up to "
                                           "16,777,216 splats, and this scene has 16,777,217"):
        check_exact_ids(files, "v.exr", EXACT_FLOAT_IDS + 1)


def test_the_docs_say_which_renderer_computes_which_layer(tmp_path, capsys):
    """The README said "every renderer computes every layer"; the CPU renderer draws colour,
    alpha and depth and refuses the others in one line, and the docs now say so."""
    from helpers import REPO

    readme = (REPO / "README.md").read_text()
    reference = (REPO / "docs" / "cli.md").read_text()     # the command reference (issue 39)
    layers_doc = (REPO / "docs" / "layers.md").read_text()
    for page in (readme, reference):
        assert "Every renderer computes every layer" not in page
        assert "`--renderer cpu` computes colour, alpha and depth and refuses the rest" in page
    assert "All three renderers (quad, tile, reference) compute every layer" not in layers_doc
    assert "computes colour, alpha and depth only and refuses the other" in layers_doc
    from splatgl.renderers.cpu import LAYERS
    assert LAYERS == with_layers(Layer.DEPTH)     # what the docs say it draws
    for layer in ("median-depth", "normal", "count", "top-id"):
        assert main(["render", "--renderer", "cpu", "--layers", layer, "-o",
                     str(tmp_path / f"{layer}.exr")] + ARGS) == 2
        err = capsys.readouterr().err
        assert err == (f"splatgl: error: --renderer cpu draws colour, alpha and depth only, not "
                       f"{layer} (use --renderer quad)\n")


def test_a_path_with_layers_alpha_writes_its_picture_per_frame(tmp_path, capsys):
    """--layers alpha (colour and alpha: the frame's own layers) wrote no alpha picture, and
    --resume then found every frame incomplete and rendered it again."""
    out = tmp_path / "a"
    assert main(["render", "--path", "orbit:2", "-o", f"{out}/", "--layers", "alpha"] + ARGS) == 0
    assert sorted(p.name for p in out.iterdir()) == ["00000.png", "00000_alpha.png", "00001.png",
                                                     "00001_alpha.png"]
    capsys.readouterr()
    assert main(["render", "--path", "orbit:2", "-o", f"{out}/", "--layers", "alpha",
                 "--resume"] + ARGS) == 0
    assert "wrote 0 frames" in capsys.readouterr().out
