"""Splats composited into a render of opaque geometry (``--under``, splatgl/output/under.py; its
files splatgl/imagefiles/under_exr.py),
checked against closed forms: a plane at a known depth through a scene (the result is the
splats in front of it over the plane's colour), a single splat before or behind a plane, and a
box drawn by the project's mesh rasterizer (whose depth is checked against ray casting).

Tolerances: the reference and the tile renderer agree to float32 rounding (1e-5); the quad
path as for colour against the reference (docs/results/summary.md: max 0.006-0.027 on real scenes; 0.02 here).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

import helpers
from helpers import GPU_DEPTH_RTOL, IN_DEPTH, random_scene, scene_with_colors
from splatgl.api import render_reference_layers
from splatgl.cameras.camera import Camera
from splatgl.cameras.poses import look_at
from splatgl.cameras.view import View
from splatgl.cli import main
from splatgl.errors import CameraError, SplatglError
from splatgl.scene.splats import Scene
from splatgl.scene.settings import RendererKind, RenderSettings
from splatgl.imagefiles.images import read_image, write_image
from splatgl.output.layers import Layer, with_layers
from splatgl.imagefiles.under_exr import read_under, write_under
from splatgl.output.under import DepthKind, UnderImage
from splatgl.reference.pixel import pixel_splats
from splatgl.renderers.mesh import MeshRenderer
from splatgl.splatmath import mesh as meshes
from splatgl.splatmath import project as pm

DEPTH = with_layers(Layer.DEPTH)
KINDS = (RendererKind.REFERENCE, RendererKind.QUAD, RendererKind.TILE)
TOLERANCE = {RendererKind.REFERENCE: 1e-5, RendererKind.TILE: 1e-5, RendererKind.QUAD: 0.02}
CAMERA = Camera(64, 48, 56.0, 56.0, 32.0, 24.0)


def _render(gl_renderer, kind, scene, camera, settings, under, layers=DEPTH):
    if kind is RendererKind.REFERENCE:
        return render_reference_layers(scene, camera, settings, layers=layers, under=under)
    return gl_renderer.render_layers(scene, camera, settings, kind, layers=layers, under=under)


def _flat(camera, rgb, depth, alpha=1.0, kind=DepthKind.Z):
    h, w = camera.height, camera.width
    return UnderImage(np.full((h, w, 3), rgb, np.float32) * alpha, np.full((h, w), alpha, np.float32),
                      np.full((h, w), depth, np.float32), kind, Path("plane.exr"))


@pytest.mark.parametrize("kind", KINDS)
def test_single_splat_before_and_behind_a_plane(gl_renderer, kind):
    scene = scene_with_colors([[0.0, 0.0, 5.0]], [[1.0, 0, 0, 0]], [[0.6, 0.4, 0.1]], [0.8],
                              [[0.9, 0.2, 0.1]])
    settings = RenderSettings(background=(0.0, 0.0, 1.0))
    plain = _render(gl_renderer, kind, scene, CAMERA, settings, None)
    a = plain.alpha[..., None]
    u = np.array([0.2, 0.7, 0.3], np.float32)
    behind = _render(gl_renderer, kind, scene, CAMERA, settings, _flat(CAMERA, u, 6.0))
    # splat over the plane: C + T U (the background is hidden by the opaque plane)
    expected = plain.rgba[..., :3] - (1 - a) * [0.0, 0.0, 1.0] + (1 - a) * u
    np.testing.assert_allclose(behind.rgba[..., :3], expected, atol=TOLERANCE[kind])
    np.testing.assert_allclose(behind.alpha, 1.0, atol=1e-6)
    # the expected depth of the composite: the splat's 5 where it is opaque, the plane's 6 behind
    z = behind.expected_depth()
    np.testing.assert_allclose(z, 5.0 * a[..., 0] + 6.0 * (1 - a[..., 0]), rtol=1e-5)
    front = _render(gl_renderer, kind, scene, CAMERA, settings, _flat(CAMERA, u, 4.0))
    np.testing.assert_allclose(front.rgba[..., :3], np.broadcast_to(u, front.rgba[..., :3].shape), atol=1e-6)
    # a half-transparent plane (A 0.5, premultiplied) lets half the background through
    glass = _render(gl_renderer, kind, scene, CAMERA, settings, _flat(CAMERA, u, 4.0, alpha=0.5))
    np.testing.assert_allclose(glass.rgba[0, 0, :3], 0.5 * u + 0.5 * np.array([0, 0, 1.0]), atol=1e-6)
    np.testing.assert_allclose(glass.alpha[0, 0], 0.5, atol=1e-6)


def _depths(scene, camera, settings):
    view = View.of(camera, settings, scene)
    means, cam = pm.anchored(scene.means, view.anchor, view.camera, np.float64)
    return pm.to_camera(means, cam)[:, 2], view


@pytest.mark.parametrize("kind", KINDS)
def test_plane_through_a_scene_keeps_the_splats_in_front(gl_renderer, kind):
    """A plane at view z0 through the scene: the composite is the scene's splats with centres
    in front of z0, blended over the plane's colour: to float32 rounding, in every renderer."""
    scene = random_scene(800, seed=2, **IN_DEPTH)
    settings = RenderSettings(background=(0.1, 0.2, 0.3))
    z, view = _depths(scene, CAMERA, settings)
    z0 = float(np.median(z))
    u = np.array([0.6, 0.5, 0.4], np.float32)
    got = _render(gl_renderer, kind, scene, CAMERA, settings, _flat(CAMERA, u, z0))
    # the splats behind made transparent (alpha < 1/255: never blended), all else the same
    front = Scene(scene.means, scene.quats, scene.log_scales,
                  np.where(z >= z0, -40.0, scene.opacity_logits), scene.sh, scene.kind)
    expected = _render(gl_renderer, kind, front, CAMERA, RenderSettings(background=tuple(u)), None)
    # (the composite takes T as 1 - A: float32 rounding, 1e-7)
    np.testing.assert_allclose(got.rgba[..., :3], expected.rgba[..., :3], atol=1e-6)
    assert np.abs(got.rgba[..., :3] - _render(gl_renderer, kind, scene, CAMERA, settings, None)
                  .rgba[..., :3]).max() > 0.2     # the plane really cut the scene


def _box_scene():
    scene = random_scene(900, seed=12, center=(0.0, 0.0, 0.0), spread=0.8,
                         log_scale=(-3.0, 0.4), logit=(0.5, 1.5), sh_sd=0.4, wild_colors=0.0)
    camera = Camera.from_fov(72, 54, 50.0, look_at([1.0, -0.8, -2.2], [0.0, 0.0, 0.0]))
    box = meshes.box([0.1, 0.2, 0.0], [0.9, 0.7, 0.8], (0.9, 0.45, 0.2),
                     rotation=pm.quat_to_rotmat(np.array([0.9, 0.1, 0.3, 0.2])))
    return scene, camera, box


def test_mesh_renderer_depth_is_the_ray_casting_closed_form(ctx):
    _, camera, box = _box_scene()
    shape = box + meshes.plane([0, 0.6, 0], [1.5, 0, 0], [0, 0, 1.5], (0.3, 0.6, 0.3))
    for cam in (camera, Camera.orthographic(72, 54, 20.0, camera.world_to_camera)):
        img = MeshRenderer(ctx).render(shape, cam)
        z, face = meshes.ray_depth(shape, cam)
        np.testing.assert_array_equal(np.isfinite(img.depth), face >= 0)
        hit = face >= 0
        assert hit.mean() > 0.2
        np.testing.assert_allclose(img.depth[hit], z[hit], rtol=GPU_DEPTH_RTOL if helpers.GPU_GL else 2e-6)
    with pytest.raises(CameraError, match="perspective and orthographic cameras only, not fisheye"):
        MeshRenderer(ctx).render(shape, Camera.fisheye(32, 32, 180.0))


@pytest.mark.parametrize("kind", KINDS)
def test_box_inside_a_scene_composites_by_depth(ctx, gl_renderer, kind, tmp_path):
    scene, camera, box = _box_scene()
    image = MeshRenderer(ctx).render(box, camera)
    write_under(tmp_path / "box.exr", image.rgba, image.depth)
    under = read_under(tmp_path / "box.exr")            # the file says its depth is z
    assert under.kind is DepthKind.Z
    settings = RenderSettings()
    got = _render(gl_renderer, kind, scene, camera, settings, under)
    ref = render_reference_layers(scene, camera, settings, layers=DEPTH, under=under)
    np.testing.assert_allclose(got.rgba, ref.rgba, atol=TOLERANCE[kind])
    if kind is RendererKind.REFERENCE:   # the reference against each pixel's own listing
        geometry = View.of(camera, settings, scene).geometry(under)
        for y, x in [(27, 36), (20, 30), (33, 40), (5, 5)]:
            listing = pixel_splats(scene, camera, x, y, settings, under=geometry)
            np.testing.assert_allclose(listing.color, ref.rgba[y, x, :3], atol=2e-6)
            assert all(s.depth < geometry.depth[y, x] for s in listing.splats)
        inside = np.isfinite(image.depth)
        assert inside.mean() > 0.1 and (got.rgba[inside, :3] != 0).any()


def test_distance_along_the_ray_gives_the_same_composite(ctx, gl_renderer):
    scene, camera, box = _box_scene()
    image = MeshRenderer(ctx).render(box, camera)
    z_under = image.under()
    rays = np.stack(np.meshgrid((np.arange(72) + 0.5 - camera.cx) / camera.fx,
                                (np.arange(54) + 0.5 - camera.cy) / camera.fy), -1)
    length = np.sqrt((rays ** 2).sum(-1) + 1.0)
    d_under = UnderImage(z_under.rgb, z_under.alpha, (z_under.depth * length).astype(np.float32),
                         DepthKind.DISTANCE, Path("d.exr"))
    a = gl_renderer.render_layers(scene, camera, RenderSettings(), layers=DEPTH, under=z_under)
    b = gl_renderer.render_layers(scene, camera, RenderSettings(), layers=DEPTH, under=d_under)
    np.testing.assert_allclose(a.rgba, b.rgba, atol=1e-6)


def test_lens_cameras_take_distance_and_refuse_z(gl_renderer):
    scene = random_scene(400, seed=3, spread=1.0, log_scale=(-3.0, 0.5), logit=(0.5, 1.5))
    camera = Camera.fisheye(48, 48, 180.0, look_at([0.0, 0.0, -3.0], [0.0, 0.0, 0.0]))
    settings = RenderSettings()
    plane = _flat(camera, [0.5, 0.5, 0.5], 3.0, kind=DepthKind.DISTANCE)
    ref = render_reference_layers(scene, camera, settings, layers=DEPTH, under=plane)
    quad = gl_renderer.render_layers(scene, camera, settings, layers=DEPTH, under=plane)
    np.testing.assert_allclose(quad.rgba, ref.rgba, atol=0.02)
    with pytest.raises(CameraError, match="give the geometry's depth as distance along the ray"):
        gl_renderer.render_layers(scene, camera, settings, under=_flat(camera, [0.5] * 3, 3.0))


def _exr(path, attrs=None, size=(8, 6)):
    w, h = size
    write_image(path, np.ones((h, w, 4), np.float32), depth=np.full((h, w), 2.0, np.float32),
                attributes=attrs or {})
    return path


def test_geometry_files_are_checked_in_one_line(tmp_path):
    plain = _exr(tmp_path / "a.exr")
    with pytest.raises(SplatglError, match="does not say whether its depth is view-space z or "
                                           "distance along the ray; give --under-depth z or distance"):
        read_under(plain)
    assert read_under(plain, "distance").kind is DepthKind.DISTANCE
    said = _exr(tmp_path / "b.exr", {"splatgl:depth": "z"})
    with pytest.raises(SplatglError, match="the file says its depth is z"):
        read_under(said, "distance")
    with pytest.raises(SplatglError, match="no channel W"):
        read_under(said, channel="W")
    with pytest.raises(SplatglError, match="give an EXR file"):
        read_under(tmp_path / "a.png")
    with pytest.raises(SplatglError, match="the geometry is 8x6, the view 64x48"):
        View.of(CAMERA, RenderSettings(), random_scene(5, seed=1, **IN_DEPTH)).geometry(read_under(said))
    empty = tmp_path / "c.exr"
    write_image(empty, np.ones((6, 8, 4), np.float32), depth=np.zeros((6, 8), np.float32),
                attributes={"splatgl:depth": "z"})
    with pytest.raises(SplatglError, match="holds no geometry"):
        read_under(empty)


def test_cli_render_under_a_mesh(ctx, tmp_path, capsys):
    scene, camera, box = _box_scene()
    from splatgl.cameras.camera_files import save_camera
    from splatgl.formats import save_scene
    save_scene(tmp_path / "s.ply", scene)
    save_camera(tmp_path / "cam.json", camera)
    image = MeshRenderer(ctx).render(box, camera)
    write_under(tmp_path / "box.exr", image.rgba, image.depth)
    out = tmp_path / "c.exr"
    assert main(["render", str(tmp_path / "s.ply"), "--camera", str(tmp_path / "cam.json"),
                 "--under", str(tmp_path / "box.exr"), "-o", str(out)]) == 0
    got = read_image(out)
    ref = render_reference_layers(scene, camera, RenderSettings(), layers=DEPTH,
                                  under=read_under(tmp_path / "box.exr"))
    np.testing.assert_allclose(got[..., :4], ref.rgba, atol=0.02)
    spec = oiio.ImageInput.open(str(out)).spec()
    assert spec.getattribute("splatgl:depth") == "z"
    for extra, message in ((["--stereo", "0.1"], "not with --stereo"),
                           (["--width", "36"], "the geometry is 72x54, the view 36x27")):
        code = main(["render", str(tmp_path / "s.ply"), "--camera", str(tmp_path / "cam.json"),
                     "--under", str(tmp_path / "box.exr"), "-o", str(tmp_path / "x.png")] + extra)
        err = capsys.readouterr().err
        assert code == 2 and message in err and len(err.strip().splitlines()) == 1
    assert main(["render", "--path", "orbit:2", "--under", str(tmp_path / "box.exr"),
                 "-o", str(tmp_path / "f/")]) == 2
    assert "not with --path" in capsys.readouterr().err


@pytest.mark.parametrize("bad, shown", [(np.nan, "nan"), (-2.0, "-2"), (-np.inf, "-inf")])
def test_nan_or_negative_geometry_depth_is_refused(tmp_path, bad, shown):
    """0 and +inf are background (what renderers write where nothing is); NaN and negative
    depths are no depth at all: refused in one line with the count and the first pixel."""
    depth = np.full((6, 8), 3.0, np.float32)
    depth[0, 0], depth[0, 1] = 0.0, np.inf          # background: fine
    depth[2, 5] = depth[4, 1] = bad
    path = tmp_path / "g.exr"
    write_image(path, np.ones((6, 8, 4), np.float32), depth=depth, attributes={"splatgl:depth": "z"})
    with pytest.raises(SplatglError) as err:
        read_under(path)
    assert str(err.value) == (f"--under {path}: channel Z is NaN or negative (a depth is positive; "
                              f"0 or inf where there is no geometry) at 2 pixels (the first at "
                              f"x=5, y=2: {shown})")
    depth[2, 5] = depth[4, 1] = 3.0
    write_image(path, np.ones((6, 8, 4), np.float32), depth=depth, attributes={"splatgl:depth": "z"})
    under = read_under(path)
    assert np.isinf(under.depth[0, :2]).all() and (under.depth[1:] == 3.0).all()
    rgba = np.ones((6, 8, 4), np.float32)
    rgba[3, 2, 1] = np.inf
    write_image(path, rgba, depth=depth, attributes={"splatgl:depth": "z"})
    with pytest.raises(SplatglError, match=r"channel R/G/B/A is not finite at 1 pixel \(the first "
                                           r"at x=2, y=3: 1, inf, 1, 1\)"):
        read_under(path)
