"""Scene editing (issue 30): the operations' exact definitions, the expression whitelist, the
order of operations, merging with transforms, and the refusals, through the Python API
(splatgl.edit); the command line is in test_edit_cli.py."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings as hsettings, strategies as st

from helpers import random_scene
from splatgl.constants import SH_C0
from splatgl.edit import (CropBox, CropSphere, Decimate, DropInvalid, Filter, RemoveFloaters,
                          ShDegree, apply_operations, edit_scene, merge_scenes, parse_expression,
                          transform_scene)
from splatgl.edit.attributes import Rows
from splatgl.edit.statistics import attribute_statistics, overdraw
from splatgl.edit.options import crop_box, operation, remove_floaters
from splatgl.errors import SplatglError
from splatgl.scene.splats import Scene, SplatKind
from splatgl.scene.transform import SceneTransform
from splatgl.splatmath.project import quat_to_rotmat, sh_color


def points(xyz, logits=None, log_scales=None, degree=0) -> Scene:
    """A scene with centres ``xyz`` (N, 3), identity rotations, scales e^-3, opacity 0.5."""
    xyz = np.asarray(xyz, np.float64)
    n = len(xyz)
    quats = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    ls = np.full((n, 3), -3.0) if log_scales is None else log_scales
    lg = np.zeros(n) if logits is None else logits
    return Scene(xyz, quats, ls, lg, np.zeros((n, (degree + 1) ** 2, 3)))


def kept(scene: Scene, *ops) -> np.ndarray:
    """The rows of ``scene`` the operations keep (matched by their centres, all distinct)."""
    out = apply_operations(scene, ops).scene
    return np.flatnonzero(np.isin(_rows(scene.means), _rows(out.means)))


def _rows(means: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(means).view("V12").ravel()


# ------------------------------------------------------------------ crops


def test_box_keeps_its_faces_and_the_sphere_does_not():
    """Box: lo <= p <= hi (faces kept); sphere: |p - c|^2 < r^2 (the surface dropped), as
    splat-transform defines them; --invert keeps exactly the others."""
    s = points([[0, 0, 0], [1, 0.5, 0.5], [1.0001, 0.5, 0.5], [0.5, 0.5, 1], [-1e-6, 0, 0]])
    box = CropBox((0, 0, 0), (1, 1, 1))
    assert kept(s, box).tolist() == [0, 1, 3]
    assert kept(s, CropBox((0, 0, 0), (1, 1, 1), invert=True)).tolist() == [2, 4]
    t = points([[0, 0, 0], [2, 0, 0], [0, 1.9999, 0], [0, 0, -2.0001]])
    assert kept(t, CropSphere((0, 0, 0), 2.0)).tolist() == [0, 2]
    assert kept(t, CropSphere((0, 0, 0), 2.0, invert=True)).tolist() == [1, 3]


def test_a_placed_box_tests_the_points_in_its_own_frame():
    """A box placed by a transform (turned 45 degrees about z, moved, scaled) keeps exactly the
    points whose coordinates in the box's frame lie in it; the JSON form gives the same box."""
    rng = np.random.default_rng(3)
    s = points(rng.uniform(-2, 2, (400, 3)))
    turn = SceneTransform.from_euler((0, 0, 45), (0.3, 0, 0), 1.5)
    placed = kept(s, CropBox((-1, -1, -1), (1, 1, 1), transform=turn))
    local = (s.means.astype(np.float64) - turn.translation) @ np.asarray(turn.rotation) / 1.5
    assert placed.tolist() == np.flatnonzero((np.abs(local) <= 1).all(axis=1)).tolist()
    assert 0 < len(placed) < 400
    box = crop_box('{"min": [-1, -1, -1], "max": [1, 1, 1], "rotate_deg": [0, 0, 45], '
                   '"translate": [0.3, 0, 0], "scale": 1.5}')
    assert kept(s, box).tolist() == placed.tolist()


@pytest.mark.parametrize("text,message", [
    ("1,0,0,0,1,1", "--crop-box: min x 1 > max x 0: the box is empty"),
    ("0,0,0,1,1", "--crop-box '0,0,0,1,1': expected X0,Y0,Z0,X1,Y1,Z1 (6 numbers, got 5)"),
    ("0,0,nan,1,1,1", "--crop-box min: every number must be a number or +-inf, not NaN"),
    ('{"min": [0, 0, 0]}', '--crop-box: a JSON box needs "min" and "max"'),
    ('{"min": [0, 0, 0], "max": [1, 1, 1], "sclae": 2}',
     "--crop-box: unknown key(s) ['sclae'] (use rotate_deg, rotation, translate, scale)"),
    ('{"min": [0, 0, 0], "max": [1, 1, 1], "min": [-1, -1, -1]}',
     "--crop-box: key 'min' given twice in one object (JSON keeps only the last)"),
    ('{"min": [0, 0, 0], "max": 1}', '--crop-box: "max" must be a list of 3 numbers, got 1'),
])
def test_impossible_boxes_are_refused_in_one_line(text, message):
    with pytest.raises(SplatglError) as e:
        crop_box(text)
    assert str(e.value).startswith(message) and "\n" not in str(e.value)


def test_a_sphere_needs_a_positive_radius():
    with pytest.raises(SplatglError, match="radius must be a finite number > 0, got 0.0"):
        operation("crop-sphere", "0,0,0,0")


# ------------------------------------------------------------------ expressions


def test_filters_see_decoded_values_in_stated_units():
    """opacity 0-1, scales in world units (exp of the stored log), colour 0-1, anisotropy the
    ratio of scales, sh_degree the highest band holding a nonzero coefficient."""
    n = 6
    ls = np.log([[0.1, 0.1, 0.1], [0.01, 0.02, 0.5], [1, 1, 1], [0.2, 0.2, 0.002],
                 [0.3, 0.3, 0.3], [0.05, 0.05, 0.05]])
    logits = np.log(np.array([0.01, 0.5, 0.9, 0.3, 0.02, 0.7]) / (1 - np.array([0.01, 0.5, 0.9, 0.3, 0.02, 0.7])))
    s = points(np.c_[np.arange(n), np.zeros(n), np.zeros(n)], logits, ls, degree=2)
    sh = np.array(s.sh)
    sh[:, 0, 0] = (np.array([0.1, 0.9, 0.5, 0.5, 0.5, 0.95]) - 0.5) / SH_C0
    sh[1, 2, 0] = 0.1    # band 1
    sh[4, 7, 2] = -0.2   # band 2
    s = Scene(s.means, s.quats, s.log_scales, s.opacity_logits, sh)
    assert kept(s, Filter("opacity < 0.02")).tolist() == [0]
    assert kept(s, Filter("max_scale > 0.4")).tolist() == [1, 2]
    assert kept(s, Filter("anisotropy > 50")).tolist() == [1, 3]
    assert kept(s, Filter("r > 0.8 and x > 0")).tolist() == [1, 5]
    assert kept(s, Filter("sh_degree >= 1")).tolist() == [1, 4]
    assert kept(s, Filter("sh_degree == 2")).tolist() == [4]
    assert kept(s, Filter("0.2 < opacity < 0.8")).tolist() == [1, 3, 5]
    assert kept(s, Filter("opacity < 0.02 or max_scale > 0.4", invert=True)).tolist() == [3, 4, 5]
    assert kept(s, Filter("not (abs(x - 2.5) < 1) and min(scale_0, scale_1) > 0.049")).tolist() == [0, 4, 5]


@pytest.mark.parametrize("text,message", [
    ("__import__('os').system('true')", "unsupported call at column 1"),
    ("().__class__", "'().__class__' is not allowed"),
    ("x.real > 0", "'x.real' is not allowed"),
    ("opacity[0] > 1", "'opacity[0]' is not allowed"),
    ("(lambda: 1)() > 0", "unsupported call"),
    ("opacity > '0.5'", "only numbers are allowed as constants"),
    ("opacity", "is a value, not a condition"),
    ("opacity and x", "'and' joins conditions, not values"),
    ("(x < 1) < 2", "a comparison compares values, not conditions"),
    ("opcity < 0.1", "unknown attribute 'opcity' (did you mean 'opacity'?)"),
    ("opacity < 0.1 && x > 0", "'&&' is not an operator here; write 'and'"),
    ("opacity = 0.5", "syntax error at column"),
    ("opacity <", "syntax error at column 10 (the expression ends too early)"),
    ("  x y", "syntax error at column 5"),
    ("(opacity < 1", "syntax error at column 1: '(' was never closed"),
    ("x ** 2 > 1", "unsupported operator"),
    ("x in (1, 2)", "unsupported comparison"),
    ("", "empty expression"),
    ("x > 0 and " * 200 + "x > 0", "longer than 1000 characters"),
])
def test_expressions_outside_the_grammar_are_refused_without_running(text, message):
    with pytest.raises(SplatglError) as e:
        parse_expression(text)
    assert message in str(e.value) and str(e.value).startswith("--filter ")
    assert "\n" not in str(e.value)


def test_nan_compares_false_and_surfels_have_no_third_scale():
    s = points([[np.nan, 0, 0], [1, 0, 0]])
    rows = Rows(s, 0, 2)
    assert parse_expression("x > 0").evaluate(rows).tolist() == [False, True]
    assert parse_expression("not (x <= 0)").evaluate(rows).tolist() == [True, True]
    surfels = random_scene(10, kind=SplatKind.SURFEL_2D)
    with pytest.raises(SplatglError, match="2DGS surfels have no scale_2"):
        apply_operations(surfels, [Filter("scale_2 > 1")])
    assert apply_operations(surfels, [Filter("max_scale > 0")]).scene.count == 10


def test_drop_invalid_drops_nonfinite_rows_and_zero_quaternions():
    s = random_scene(8, degree=1)
    arrays = {n: np.array(getattr(s, n)) for n in ("means", "quats", "log_scales",
                                                   "opacity_logits", "sh")}
    arrays["means"][1, 2] = np.nan
    arrays["quats"][3] = 0.0
    arrays["opacity_logits"][4] = np.inf
    arrays["sh"][6, 2, 1] = -np.inf
    bad = Scene(**arrays)
    assert apply_operations(bad, [DropInvalid()]).scene.count == 4
    assert kept(bad, DropInvalid()).tolist() == [0, 2, 5, 7]


# ------------------------------------------------------------------ floaters


def test_floaters_are_isolated_and_faint_and_the_threshold_is_reported():
    """Two dense clusters and five far strays; the three faint strays go, the two opaque ones
    stay (the opacity gate), no cluster splat goes."""
    rng = np.random.default_rng(7)
    clusters = np.r_[rng.normal(0, 0.1, (300, 3)), rng.normal([3, 0, 0], 0.1, (300, 3))]
    strays = np.array([[0, 4, 0], [2, -4, 1], [-3, 0, 3], [0, 0, -5], [5, 5, 5]], float)
    opacity = np.r_[np.full(600, 0.9), [0.1, 0.2, 0.3, 0.95, 0.8]]
    s = points(np.r_[clusters, strays], np.log(opacity / (1 - opacity)))
    edited = apply_operations(s, [RemoveFloaters(neighbours=8)])
    assert edited.scene.count == 602
    gone = sorted(set(range(605)) - set(kept(s, RemoveFloaters(neighbours=8)).tolist()))
    assert gone == [600, 601, 602]
    step = edited.steps[0]
    assert step.removed == 3 and "8 neighbours" in step.parameters and "opacity < 0.5" in step.parameters
    assert "threshold" in step.detail and "world units" in step.detail
    every = RemoveFloaters(neighbours=8, opacity=1.0)
    assert sorted(set(range(605)) - set(kept(s, every).tolist())) == [600, 601, 602, 603, 604]


def test_floaters_leave_nan_centres_to_drop_invalid():
    rng = np.random.default_rng(8)
    xyz = np.r_[rng.normal(0, 0.1, (100, 3)), [[np.nan, 0, 0], [9, 9, 9]]]
    found = RemoveFloaters(neighbours=4).find(xyz, np.full(102, 0.1))
    assert found.mask.tolist() == [False] * 101 + [True]


def test_floater_parameters_from_text_and_their_refusals():
    assert remove_floaters("") == RemoveFloaters()
    assert remove_floaters("k=4,sigma=2.5,opacity=1") == RemoveFloaters(4, 2.5, 1.0)
    with pytest.raises(SplatglError, match="expected KEY=VALUE pairs"):
        remove_floaters("radius=2")
    with pytest.raises(SplatglError, match="sigma must be > 0"):
        remove_floaters("sigma=0")
    with pytest.raises(SplatglError, match=r"neighbours must be an integer 1-256, got 0$"):
        remove_floaters("neighbours=0")            # as given (it said "got 0.0")
    with pytest.raises(SplatglError, match=r"neighbours must be an integer 1-256, got 2\.5$"):
        remove_floaters("k=2.5")


# ------------------------------------------------------------------ decimation


def test_decimate_reaches_the_count_and_keeps_unmerged_splats_bit_for_bit():
    s = random_scene(1000, seed=2, degree=1)
    for op, target in ((Decimate(count=700), 700), (Decimate(percent=25), 250),
                       (Decimate.parse("12.5%"), 125), (Decimate.parse("5000"), 1000)):
        out = apply_operations(s, [op]).scene
        assert out.count == target
    out = apply_operations(s, [Decimate(count=900)]).scene
    same = np.isin(_rows(s.means), _rows(out.means))
    assert same.sum() == 800  # 100 pairs merged, 800 rows untouched
    rows_in = s.subset(same)
    rows_out = out.subset(np.isin(_rows(out.means), _rows(s.means)))
    assert np.array_equal(np.sort(rows_in.opacity_logits), np.sort(rows_out.opacity_logits))


def test_a_merged_pair_is_the_moment_match_of_the_lod_merge():
    """Two splats become one whose mean is the (opacity x area)-weighted mean and whose SH is
    the weighted SH (the LOD hierarchy's rule)."""
    s = points([[0, 0, 0], [0.02, 0, 0]], logits=np.array([0.0, 2.0]))
    sh = np.zeros((2, 1, 3))
    sh[:, 0] = [[1.0, 0, 0], [0, 1.0, 0]]
    s = Scene(s.means, s.quats, s.log_scales, s.opacity_logits, sh)
    out = apply_operations(s, [Decimate(count=1)]).scene
    w = s.opacities.astype(np.float64)   # equal areas: the weights are the opacities
    assert out.count == 1
    np.testing.assert_allclose(out.means[0], (w[:, None] * s.means).sum(0) / w.sum(), atol=1e-7)
    np.testing.assert_allclose(out.sh[0, 0], (w[:, None] * sh[:, 0]).sum(0) / w.sum(), atol=1e-6)
    assert out.scales.max() > s.scales.max()   # the spread of the means widens it


def test_decimate_refusals():
    for text, message in (("0", "the count must be an integer >= 1"),
                          ("150%", "the percentage must be in (0, 100]"),
                          ("half", "expected a count N or a percentage P%")):
        with pytest.raises(SplatglError, match=message.replace("(", r"\(").replace(")", r"\)")):
            Decimate.parse(text)
    with pytest.raises(SplatglError, match="2DGS surfels cannot be merged"):
        apply_operations(random_scene(20, kind=SplatKind.SURFEL_2D), [Decimate(count=10)])


# ------------------------------------------------------------------ order, SH, emptiness


def test_operations_run_in_the_order_given():
    """Decimating then cropping differs from cropping then decimating: the order is honoured."""
    s = random_scene(2000, seed=4, spread=1.0)
    box = CropBox((0, -5, -5), (5, 5, 5))
    first = apply_operations(s, [box, Decimate(percent=50)])
    second = apply_operations(s, [Decimate(percent=50), box])
    assert [st.name for st in first.steps] == ["crop-box", "decimate"]
    assert first.scene.count == round(first.steps[0].after / 2)
    assert second.steps[0].after == 1000 and second.scene.count != first.scene.count


def test_sh_degree_drops_bands_but_never_adds_them():
    s = random_scene(50, degree=3)
    out = apply_operations(s, [ShDegree(1)])
    assert out.scene.sh_degree == 1 and np.array_equal(out.scene.sh, s.sh[:, :4])
    assert out.steps[0].detail == "SH degree 3 -> 1"
    assert apply_operations(random_scene(5, degree=1), [ShDegree(3)]).scene.sh_degree == 1
    with pytest.raises(SplatglError, match="--sh-degree must be an integer 0-3, got 4"):
        ShDegree(4)


def test_an_empty_result_is_refused_unless_allowed():
    s = random_scene(20)
    far = CropSphere((100, 100, 100), 1.0)
    with pytest.raises(SplatglError, match="no splats left"):
        edit_scene(s, far)
    assert edit_scene(s, far, allow_empty=True).count == 0


def test_nothing_is_copied_when_nothing_changes():
    s = random_scene(30)
    assert apply_operations(s, [Filter("opacity >= 0")]).scene is s


# ------------------------------------------------------------------ placement and merging


def test_a_baked_transform_keeps_every_splats_look():
    """Means, rotations and scales follow p -> s R p + t; the SH is rotated so the colour seen
    along any world direction d is the old colour along R^T d (degree 3)."""
    s = random_scene(40, seed=5, degree=3)
    t = SceneTransform.from_euler((30, -50, 70), (1, 2, 3), 1.7)
    out = transform_scene(s, t)
    r = np.asarray(t.rotation)
    np.testing.assert_allclose(out.means, t.apply_points(s.means), atol=1e-5)
    np.testing.assert_allclose(quat_to_rotmat(out.rotations.astype(np.float64)),
                               r @ quat_to_rotmat(s.rotations.astype(np.float64)), atol=1e-6)
    np.testing.assert_allclose(out.scales, 1.7 * s.scales, rtol=1e-5)
    d = np.random.default_rng(1).normal(size=(40, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    np.testing.assert_allclose(sh_color(out.sh.astype(np.float64), d),
                               sh_color(s.sh.astype(np.float64), d @ r), atol=1e-5)
    assert transform_scene(s, SceneTransform()) is s


def test_merge_pads_sh_by_coefficient_and_keeps_input_order():
    a, b = random_scene(5, seed=1, degree=0), random_scene(7, seed=2, degree=2)
    m = merge_scenes([a, b], [None, SceneTransform(translation=(5, 0, 0))])
    assert m.count == 12 and m.sh_degree == 2
    assert np.array_equal(m.sh[:5, 0], a.sh[:, 0]) and not m.sh[:5, 1:].any()
    np.testing.assert_allclose(m.means[5:], b.means + [5, 0, 0], atol=1e-6)
    assert merge_scenes([a, b], sh_degree=1).sh_degree == 1
    with pytest.raises(SplatglError, match="cannot merge 3DGS Gaussians with 2DGS surfels"):
        merge_scenes([a, random_scene(3, kind=SplatKind.SURFEL_2D)])
    with pytest.raises(SplatglError, match="1 transform"):
        merge_scenes([a, b], [None])


def test_selecting_holds_a_mask_and_the_result_not_a_second_scene(monkeypatch):
    """Bounded memory: a crop keeping half of 200k splats (SH 1) peaks at about the kept rows'
    size plus a block's temporaries, not at another copy of the input."""
    import tracemalloc

    s = random_scene(200_000, seed=3, degree=1, spread=1.0)
    s_bytes = sum(getattr(s, n).nbytes for n in ("means", "quats", "log_scales",
                                                 "opacity_logits", "sh"))
    tracemalloc.start()
    out = apply_operations(s, [CropBox((0, -9, -9), (9, 9, 9)), Filter("opacity > 0.01")]).scene
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert 0.4 < out.count / s.count < 0.6
    assert peak < 0.6 * s_bytes + 8e6, f"peak {peak / 1e6:.1f} MB for a {s_bytes / 1e6:.1f} MB scene"


# ------------------------------------------------------------------ issue 38: limits and notes


@pytest.mark.parametrize("n", [2, 3, 7, 9, 10000])
def test_decimate_reaches_one_splat_through_an_odd_round(n):
    """An odd round that starts at two splats has no pair at offset 1: it pairs from row 0
    (it raised 'need at least one array to concatenate')."""
    s = random_scene(n, seed=n)
    for op in (Decimate(count=1), Decimate.parse("0.01%")):
        assert apply_operations(s, [op]).scene.count == 1


@given(st.integers(1, 40), st.floats(0.0, 1.0), st.booleans(), st.integers(0, 1000))
@hsettings(max_examples=150)
def test_decimate_reaches_every_small_target(n, share, percent, seed):
    s = random_scene(n, seed=seed, spread=1.0)
    op = (Decimate(percent=max(1e-3, 100.0 * share)) if percent
          else Decimate(count=1 + int(share * (n + 3))))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = apply_operations(s, [op]).scene
    assert out.count == op.target(n) and np.isfinite(out.means).all()


def test_decimate_above_the_count_says_nothing_merged_and_counts_are_singular():
    step = apply_operations(random_scene(3), [Decimate(count=5)]).steps[0]
    assert step.removed == 0
    assert step.detail == "the scene has 3 splats, not more than 5: nothing merged"
    assert Decimate(count=1).describe().startswith("to 1 splat by ")
    assert apply_operations(random_scene(9), [Decimate(count=5)]).steps[0].detail == ""


def test_floaters_on_a_tiny_scene_say_why_none_is_removed():
    step = apply_operations(random_scene(5), [RemoveFloaters(neighbours=16)]).steps[0]
    assert step.removed == 0 and "inf" not in step.detail
    assert step.detail == ("5 splats, not more than the 16 neighbours: none can be isolated, "
                           "none removed")


def test_index_is_the_row_in_the_input_and_is_refused_after_decimate():
    s = random_scene(50, seed=5)
    assert kept(s, Filter("index == 7", invert=True)).tolist() == [i for i in range(50) if i != 7]
    crop = CropBox((-np.inf, -np.inf, -np.inf), (np.inf, np.inf, 0.0))
    below = kept(s, crop)
    # after a crop the rows keep their input numbers
    assert kept(s, crop, Filter("index >= 20")).tolist() == [i for i in below if i >= 20]
    with pytest.raises(SplatglError, match="'index' is the splat's row in the input, which "
                                           "--decimate renumbers: put this filter before"):
        apply_operations(s, [Decimate(count=10), Filter("index < 3", invert=True)])
    assert "index" not in attribute_statistics(s)


def test_extreme_stored_values_raise_no_numpy_warning():
    """Positions at float32's limits, huge and tiny log-scales, logits and SH: every operation,
    the statistics and the overdraw run with warnings as errors; decimating scales whose
    moments overflow is refused in one line."""
    s = random_scene(64, seed=3, degree=1)
    means, ls = np.array(s.means), np.array(s.log_scales)
    logits, sh = np.array(s.opacity_logits), np.array(s.sh)
    means[:8] = [3e38, -3e38, 1e38]
    ls[10:14], ls[14:18], ls[18] = 99.0, -1000.0, -3e38
    logits[20:24], logits[24:28], sh[30:34] = 1e30, -1e30, 3e38
    wild = Scene(means, s.quats, ls, logits, sh)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for op in (CropBox((-1e30,) * 3, (1e30,) * 3), CropSphere((0, 0, 0), 1e308),
                   CropSphere((1e308, 0, 0), 1.0), RemoveFloaters(neighbours=4),
                   Filter("anisotropy > 2 or distance > 1e30 or max_scale < 1"),
                   Decimate(count=5), ShDegree(0),
                   CropBox((0, 0, 0), (1, 1, 1), SceneTransform(scale=1e-300))):
            apply_operations(wild, [op])
        attribute_statistics(wild)
        assert overdraw(wild)["not_estimated"].startswith("cannot frame the scene: its centre")
        assert overdraw(Scene(means[8:], s.quats[8:], ls[8:], logits[8:], sh[8:]))["per_pixel"] > 0
        ls[18] = 3e38
        with pytest.raises(SplatglError, match="--decimate: splat 18 has a scale above e.100 "
                                               "world units, whose moments overflow"):
            apply_operations(Scene(means, s.quats, ls, logits, sh), [Decimate(count=5)])


@pytest.mark.parametrize("transform", [SceneTransform(translation=(1e39, 0, 0)),
                                       SceneTransform(scale=1e300)])
def test_a_transform_beyond_float32_is_refused(transform):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(SplatglError) as e:
            transform_scene(random_scene(10), transform, "--transform of a.ply")
    assert str(e.value).startswith("--transform of a.ply (") and "\n" not in str(e.value)
    assert "beyond float32's range (|coordinate| <= 3.4e38): its position would be infinite" \
        in str(e.value)


def test_crops_take_infinite_bounds_and_huge_radii():
    s = random_scene(100, seed=6)
    half = CropBox((-np.inf, -np.inf, -np.inf), (np.inf, np.inf, 0.0))
    assert kept(s, half).tolist() == np.flatnonzero(s.means[:, 2] <= 0).tolist()
    assert crop_box("-inf,-inf,-inf,inf,inf,0") == half
    assert kept(s, CropSphere((0, 0, 0), 1e308)).size == 100
