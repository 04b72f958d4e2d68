"""compare --image: another program's image against the reference, with its size, y direction,
alpha convention and background checked (splatgl/measure/evaluation/their_image.py), and --explain."""

from __future__ import annotations

import json

import numpy as np
import OpenImageIO as oiio
import pytest

from splatgl.cli import main
from splatgl.errors import SplatglError
from splatgl.measure.evaluation.their_image import match_to_reference, read_their_image
from splatgl.imagefiles.images import write_image


def write_raw(path, pixels: np.ndarray, kind=oiio.UINT16) -> None:
    """Write (H, W, C) floats as stored values (no alpha association), 16-bit or float."""
    h, w, c = pixels.shape
    spec = oiio.ImageSpec(w, h, c, kind)
    spec.attribute("oiio:UnassociatedAlpha", 1)
    if c == 4:
        spec.channelnames = ("R", "G", "B", "A")
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec)
    data = pixels if kind == oiio.FLOAT else np.round(np.clip(pixels, 0, 1) * 65535).astype(np.uint16)
    assert out.write_image(np.ascontiguousarray(data))
    out.close()


def reference_pair(seed=0, h=24, w=32):
    """A made-up 'reference': an asymmetric picture with an empty border."""
    rng = np.random.default_rng(seed)
    alpha = np.zeros((h, w))
    alpha[4:20, 3:22] = rng.uniform(0.3, 1.0, (16, 19))
    colour = rng.uniform(0, 1, (h, w, 3)) * alpha[..., None]     # premultiplied C
    return colour, alpha


def test_size_messages(tmp_path):
    img = np.zeros((24, 30, 4), np.float32)
    write_image(tmp_path / "a.png", img)
    with pytest.raises(SplatglError, match=r"a.png: the image is 30x24, the camera 32x24: 2 pixels "
                                           r"narrower, a few pixels off"):
        read_their_image(tmp_path / "a.png", 32, 24)
    with pytest.raises(SplatglError, match="width and height swapped"):
        read_their_image(tmp_path / "a.png", 24, 30)
    with pytest.raises(SplatglError, match="same aspect at another size; pass --width 30 --height 24"):
        read_their_image(tmp_path / "a.png", 60, 48)
    with pytest.raises(SplatglError, match="no such file"):
        read_their_image(tmp_path / "b.png", 32, 24)
    assert read_their_image(tmp_path / "a.png", 30, 24).rgb.shape == (24, 30, 3)


def test_flipped_image_is_named_not_scored(tmp_path):
    colour, alpha = reference_pair()
    write_raw(tmp_path / "f.tif", colour[::-1])
    img = read_their_image(tmp_path / "f.tif", 32, 24)
    with pytest.raises(SplatglError, match=r"f.tif: looks upside down .* pass --flip-y"):
        match_to_reference(img, colour, alpha)
    turned = match_to_reference(img, colour, alpha, flip=True)
    assert np.abs(turned.rgb - colour).max() < 1e-4 and "flipped in y" in turned.notes[0]
    write_raw(tmp_path / "m.tif", colour[:, ::-1])
    with pytest.raises(SplatglError, match="mirrored left to right"):
        match_to_reference(read_their_image(tmp_path / "m.tif", 32, 24), colour, alpha)


@pytest.mark.parametrize("convention", ["straight", "premultiplied"])
def test_alpha_convention_found_and_stated(tmp_path, convention):
    colour, alpha = reference_pair(1)
    bg = np.array([0.2, 0.4, 0.6])
    truth = colour + (1 - alpha[..., None]) * bg
    with np.errstate(invalid="ignore", divide="ignore"):
        stored = colour / alpha[..., None] if convention == "straight" else colour
    stored = np.nan_to_num(stored)
    write_raw(tmp_path / "a.exr", np.concatenate([stored, alpha[..., None]], -1).astype(np.float32),
              oiio.FLOAT)
    got = match_to_reference(read_their_image(tmp_path / "a.exr", 32, 24), truth, alpha, bg)
    assert got.convention == convention
    assert np.abs(got.rgb - truth).max() < 1e-5
    assert got.notes[0].startswith(f"alpha read as {convention} (closest to the reference")
    forced = match_to_reference(read_their_image(tmp_path / "a.exr", 32, 24), truth, alpha, bg,
                                alpha=convention)
    assert forced.convention == convention and forced.notes == (f"alpha read as {convention} (--alpha)",)
    with pytest.raises(SplatglError, match="the image shows 0,0,0, not the background 0.2,0.4,0.6"):
        match_to_reference(read_their_image(tmp_path / "a.exr", 32, 24), truth, alpha, bg,
                           alpha="composited")     # read as composited, the background is missing


def test_background_mismatch_is_named(tmp_path):
    colour, alpha = reference_pair(2)
    white = colour + (1 - alpha[..., None]) * 1.0
    write_raw(tmp_path / "w.png", white)
    img = read_their_image(tmp_path / "w.png", 32, 24)
    assert img.bits == 16
    with pytest.raises(SplatglError, match=r"w.png: where the reference is empty \(\d+% of the pixels\) "
                                           r"the image shows 1,1,1, not the background 0,0,0: pass "
                                           r"--background 1,1,1"):
        match_to_reference(img, colour, alpha)
    ok = match_to_reference(img, white, alpha, (1.0, 1.0, 1.0))
    assert np.abs(ok.rgb - white).max() < 1e-4


def test_cli_image_scores_explains_and_refuses(tmp_path, capsys):
    base = ["--width", "64", "--height", "48"]
    assert main(["render", "-o", str(tmp_path / "q.exr"), "--extent", "fast"] + base) == 0
    out = tmp_path / "r.json"
    assert main(["compare", "--image", str(tmp_path / "q.exr"), "--explain", "--json", str(out)] + base) == 0
    report = json.loads(out.read_text())
    assert report["renderer"] == "q.exr" and report["alpha_convention"] == "premultiplied"
    assert report["explain"]["best"] == "extent=fixed-quad"        # the fast extent's quads
    assert report["explain"]["combination"][0]["gain_db"] > 5
    capsys.readouterr()
    pixels = oiio.ImageInput.open(str(tmp_path / "q.exr"))
    data = pixels.read_image(oiio.FLOAT)
    pixels.close()
    write_image(tmp_path / "flip.exr", np.ascontiguousarray(data[::-1, :, :4]))
    assert main(["compare", "--image", str(tmp_path / "flip.exr")] + base) == 2
    assert "flip.exr: looks upside down" in capsys.readouterr().err
    assert main(["compare", "--flip-y"] + base) == 2
    assert "apply to --image" in capsys.readouterr().err


@pytest.mark.parametrize("damage", ["cut", "crc"])
def test_a_damaged_png_is_one_line_without_libpng_s_own(tmp_path, capfd, damage):
    """libpng printed its own ``libpng error: IDAT: CRC error`` line above splatgl's."""
    good = tmp_path / "good.png"
    write_image(good, np.random.default_rng(0).random((32, 32, 4), np.float32))
    data = bytearray(good.read_bytes())
    if damage == "cut":
        data = data[:len(data) // 2]
    else:
        data[120:180] = bytes(60)          # inside IDAT: its CRC no longer matches
    bad = tmp_path / "bad.png"
    bad.write_bytes(bytes(data))
    rc = main(["compare", "--image", str(bad), "--width", "32", "--height", "32"])
    out, err = capfd.readouterr()
    assert rc == 2 and out == "" and "libpng" not in err and len(err.splitlines()) == 1, err
    assert err.startswith(f"splatgl: error: --image {bad}: ")
