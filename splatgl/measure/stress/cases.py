"""The stress cases: scenes and cameras built to break renderers, each with its error bounds.

A case builds a :class:`Setup` (scene, camera, settings and, where the renderer's defined
behaviour differs from rendering the scene as given, the scene the float64 reference renders
as the expected image).  Its :class:`Bounds` state the largest max-abs RGBA error against the
float64 reference each renderer may show, and why (see ``BOUND_NOTES``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ...cameras.camera import Camera
from ...cameras.poses import look_at
from ...scene.splats import Scene, SplatKind
from ...scene.settings import Precision, RenderSettings
from ...scene.quaternion import quat_axis_angle, quat_multiply
from .build import HEIGHT, WIDTH, at_pixel, front_camera, splats

#: Why the default bounds are what they are (printed with the report).
BOUND_NOTES = {
    "quad": "0.03 = the early stop the quad path cannot do (the dropped splat weighs <= 0.0099 "
            "x its colour, colours <= 0.95 here) + the tails the reference's tile rectangle "
            "cuts up to ~1 px short of 3 sigma (alpha <= 0.016 measured on real scenes, "
            "docs/results/summary.md) + float32 rounding",
    "tile": "1e-4 = float32 rounding of the reference's own rules: positions and conics carry "
            "~6e-8 relative error (relative to the scene anchor), ~1e-5 px at these image "
            "sizes, ~1e-5 of alpha per layer; 10x margin for a few layers.  A splat sitting "
            "exactly on the 1/255 cut or the T < 1e-4 stop could flip (up to 1/255 x colour); "
            "none does in these cases",
    "cpu": "1e-4, the same derivation as tile (the reference's rules in float32, compiled; "
           "its own exp, to 3e-6 relative, and fused multiply-adds add rounding of the same size)",
    "reference32": "1e-4, the same derivation as tile (the same float32 arithmetic in NumPy)",
}


@dataclass(frozen=True)
class Bounds:
    """Largest allowed max-abs RGBA error against the float64 reference, per renderer."""

    quad: float = 0.03
    tile: float = 1e-4
    cpu: float = 1e-4
    reference32: float = 1e-4
    why: str = ""

    def of(self, renderer: str) -> float:
        return float(getattr(self, renderer))


@dataclass(frozen=True)
class Setup:
    """What a case renders.  ``expected_scene``: what the float64 reference renders as the
    truth (None: ``scene`` itself), e.g. the scene without the splats a renderer must skip."""

    scene: Scene
    camera: Camera
    settings: RenderSettings = RenderSettings()
    expected_scene: Scene | None = None


@dataclass(frozen=True)
class StressCase:
    """One stress case.

    Attributes:
        name: short identifier (``splatgl stress --case NAME``).  what: one-line description.
        build: returns the :class:`Setup`.  bounds: error bounds per renderer.
        unsupported: renderer -> reason, for renderers that must refuse the case with a clear
            error (the report shows it; any other exception is a failure).
        known: renderer -> reason, for failures measured and understood but not fixed (the
            report shows them as KNOWN; tests mark them xfail).
        slow: large cases that the fast test run leaves to the slow marker.
    """

    name: str
    what: str
    build: Callable[[], Setup]
    bounds: Bounds = Bounds()
    unsupported: dict = field(default_factory=dict)
    known: dict = field(default_factory=dict)
    slow: bool = False


# ------------------------------------------------------------------------------ scale, shape
def _scales() -> Setup:
    cam = front_camera()
    exps = np.arange(-8, 5)
    means = [at_pixel(cam, 8 + 4 * i, 24 + (i % 2) * 8, 5.0 + 0.01 * i) for i in range(len(exps))]
    s = 10.0 ** exps
    return Setup(splats(means, np.stack([s, s, s], 1), opacities=np.full(len(s), 0.3)), cam)


def _aniso(tilt_deg: float) -> Callable[[], Setup]:
    """A needle (1 : 1e-6 : 1e-6) and a pancake (1 : 1 : 1e-6), tilted out of the image plane by
    ``tilt_deg`` (0 face-on, 90 edge-on), the needle also turned 30 degrees in the plane."""
    def build() -> Setup:
        cam = front_camera()
        needle = quat_multiply(quat_axis_angle([0, 0, 1], 30.0), quat_axis_angle([0, 1, 0], tilt_deg))
        pancake = quat_multiply(quat_axis_angle([0, 0, 1], 30.0), quat_axis_angle([1, 0, 0], tilt_deg))
        means = [at_pixel(cam, 20, 24, 5.0), at_pixel(cam, 44, 24, 5.2)]
        scales = [[0.6, 6e-7, 6e-7], [0.6, 0.6, 6e-7]]
        return Setup(splats(means, scales, [needle, pancake]), cam)
    return build


def _det_nonpositive() -> Setup:
    """Needles so long on screen (1e3 : 1e-6) that a*c - b^2 of the dilated 2D covariance
    cancels to zero or below in float32 at 45 degrees, though it is 0.6 lambda + 0.09 > 0."""
    cam = front_camera()
    q = [quat_axis_angle([0, 0, 1], 45.0), quat_axis_angle([0, 0, 1], -30.0),
         quat_multiply(quat_axis_angle([0, 0, 1], 45.0), quat_axis_angle([1, 0, 0], 60.0))]
    means = [at_pixel(cam, 32, 24, 5.0), at_pixel(cam, 20, 30, 6.0), at_pixel(cam, 40, 20, 7.0)]
    scales = [[1e3, 1e-6, 1e-6], [3e2, 1e-6, 1e-6], [1e3, 1e3, 1e-6]]
    return Setup(splats(means, scales, q, opacities=[0.3, 0.3, 0.3]), cam)


# ------------------------------------------------------------------------------ quaternions
def _quat_norms() -> Setup:
    cam = front_camera()
    norms = 10.0 ** np.arange(-6, 7)
    q = quat_multiply(quat_axis_angle([0, 0, 1], 40.0), quat_axis_angle([1, 0, 0], 30.0))
    means = [at_pixel(cam, 6 + 4.5 * i, 16 + (i % 3) * 8, 5.0 + 0.01 * i) for i in range(len(norms))]
    scales = np.tile([0.5, 0.08, 0.02], (len(norms), 1))
    scene = splats(means, scales, np.outer(norms, q))
    return Setup(scene, cam, expected_scene=splats(means, scales, np.tile(q, (len(norms), 1))))


def _zero_quats() -> Setup:
    """Zero and sub-1e-12 quaternions (the loaders reject them; a Scene built directly can hold
    them): the defined behaviour is to skip those splats, so the truth is the scene without."""
    cam = front_camera()
    means = [at_pixel(cam, 12 + 10 * i, 24, 5.0 + 0.1 * i) for i in range(5)]
    q = np.array([[1, 0, 0, 0], [0, 0, 0, 0], [0.6, 0.8, 0, 0], [1e-30, 0, 0, 0], [0, 0, 0, 0]])
    scales = np.tile([0.4, 0.2, 0.3], (5, 1))
    keep = np.array([True, False, True, False, False])
    scene = splats(means, scales, q)
    return Setup(scene, cam, expected_scene=scene.subset(keep))


# ------------------------------------------------------------------------------ placement
def _near_plane() -> Setup:
    """Camera at the origin (world = camera axes), near 0.1: splats just past the near plane and
    crossing it, exactly on it, at z = 0 and behind the camera, over a backdrop."""
    cam = Camera.from_fov(WIDTH, HEIGHT, 60.0)
    means = [[0.0, 0.0, 0.1 + 1e-6], [0.05, 0.0, 0.3], [0.0, 0.02, 0.1], [0.0, 0.0, 0.0],
             [0.0, 0.0, -1.0], [0.3, 0.1, 1e-7], [0.0, 0.0, 4.0]]
    scales = [[1.0, 1.0, 1.0], [0.5, 0.5, 0.5], [0.3, 0.3, 0.3], [1.0, 1.0, 1.0],
              [2.0, 2.0, 2.0], [0.2, 0.2, 0.2], [1.0, 1.0, 1.0]]
    opac = [0.3, 0.4, 0.5, 0.9, 0.9, 0.9, 0.9]
    return Setup(splats(means, scales, opacities=opac), cam, RenderSettings(near=0.1))


def _near_tiny() -> Setup:
    """A near plane of 1e-8 and splats just past it: the 2D covariance reaches 1e20 px^2, so
    a*c overflows float32 (the correct image is a nearly uniform veil of opacity o).  The whole
    scene lies within 3e-6 of the camera: float32 positions are relative to the scene's centre,
    so a larger scene could not place a splat 2e-8 from the camera at all."""
    cam = Camera.from_fov(WIDTH, HEIGHT, 60.0)
    means = [[0.0, 0.0, 2e-8], [1e-8, 0.0, 5e-7], [0.0, 0.0, 3e-6]]
    scales = [[10.0, 10.0, 10.0], [1e-7, 1e-7, 1e-7], [1e-6, 1e-6, 1e-6]]
    return Setup(splats(means, scales, opacities=[0.3, 0.3, 0.9]), cam, RenderSettings(near=1e-8))


def _border() -> Setup:
    """Splat centres exactly on the image border, its corners and on tile boundaries."""
    cam = front_camera()
    uv = [(0, 0), (WIDTH, 0), (0, HEIGHT), (WIDTH, HEIGHT), (0, 24), (WIDTH, 24), (32, 0),
          (32, HEIGHT), (16, 16), (48, 32), (0.5, 0.5), (WIDTH - 0.5, HEIGHT - 0.5)]
    means = [at_pixel(cam, u, v, 5.0 + 0.01 * i) for i, (u, v) in enumerate(uv)]
    return Setup(splats(means, np.full((len(uv), 3), 0.1)), cam)


def _offscreen_huge() -> Setup:
    """Splats far off screen (up to 1e6 px away) whose huge extent still covers the image."""
    cam = front_camera()
    means = [at_pixel(cam, -1e6, 24, 5.0), at_pixel(cam, 32, -2e5, 6.0),
             at_pixel(cam, 1e4, 1e4, 7.0), at_pixel(cam, 32, 24, 8.0), at_pixel(cam, 5e7, 24, 5.0)]
    scales = [[1e5, 1e5, 1e5], [3e4, 1e3, 1e3], [2e3, 2e3, 2e3], [0.5, 0.5, 0.5], [1e-2, 1e-2, 1e-2]]
    return Setup(splats(means, scales, opacities=[0.2, 0.3, 0.4, 0.8, 0.9]), cam)


def _far_origin(offset: float) -> Callable[[], Setup]:
    """A 5 x 5 grid of splats (SH degree 1) at ``offset`` from the origin, camera 8 units away:
    float32 ``R p + t`` on raw coordinates loses everything below ~offset * 6e-8."""
    def build() -> Setup:
        origin = np.array([offset, 0.5 * offset, -offset])
        grid = np.stack(np.meshgrid(np.arange(5.0) - 2, np.arange(5.0) - 2), -1).reshape(-1, 2)
        means = origin + np.concatenate([grid, np.zeros((25, 1))], 1)
        rest = np.zeros((25, 3, 3))
        rest[:, 2] = [0.8, -0.4, 0.2]                  # colour varies with the view direction
        scene = splats(means, np.full((25, 3), 0.35), sh_rest=rest)
        pose = look_at(origin + [0.3, 0.2, -8.0], origin, (0.0, -1.0, 0.0))
        return Setup(scene, Camera.from_fov(WIDTH, HEIGHT, 60.0, pose))
    return build


def _fov(degrees: float) -> Callable[[], Setup]:
    def build() -> Setup:
        rng = np.random.default_rng(7)
        if degrees < 1.0:  # telephoto: a 5-unit cluster 2000+ units away fills the frame
            dist = 0.5 * HEIGHT / math.tan(math.radians(degrees) / 2.0) * 5.0 / WIDTH
            means = np.c_[rng.uniform(-2.5, 2.5, (30, 2)), rng.uniform(-1.0, 1.0, 30)]
            scales = rng.uniform(0.1, 0.4, (30, 3))
        else:              # fisheye-wide: splats in every direction up to 80 deg off axis
            dist = 0.0
            ang = np.radians(rng.uniform(0.0, 80.0, 40))
            phi = rng.uniform(0.0, 2 * math.pi, 40)
            means = 3.0 * np.c_[np.sin(ang) * np.cos(phi), np.sin(ang) * np.sin(phi), np.cos(ang)]
            scales = rng.uniform(0.2, 0.6, (40, 3))
        cam = front_camera(dist, degrees) if dist else Camera.from_fov(WIDTH, HEIGHT, degrees)
        q = rng.normal(size=(len(means), 4))
        return Setup(splats(means, scales, q, opacities=rng.uniform(0.3, 0.9, len(means))), cam)
    return build


def _ortho(pixels_per_unit: float) -> Callable[[], Setup]:
    """Orthographic camera with tiny or huge zoom; the scene sized to fill the image, placed
    at 1 + its own size from the origin (so huge zoom also magnifies float32 rounding)."""
    def build() -> Setup:
        rng = np.random.default_rng(3)
        unit = 1.0 / pixels_per_unit            # one pixel in world units
        centre = np.array([1.0, 1.0, 0.0]) * (1.0 + 40 * unit)
        means = centre + np.c_[rng.uniform(-28, 28, 20), rng.uniform(-20, 20, 20),
                               rng.uniform(-10, 10, 20)] * unit
        scales = rng.uniform(1.0, 5.0, (20, 3)) * unit
        pose = look_at(centre - [0.0, 0.0, 1.0 + 50 * unit], centre, (0.0, -1.0, 0.0))
        cam = Camera.orthographic(WIDTH, HEIGHT, pixels_per_unit, pose)
        return Setup(splats(means, scales, rng.normal(size=(20, 4))), cam)
    return build


# ------------------------------------------------------------------------------ opacity, count
def _opacity_extremes() -> Setup:
    cam = front_camera()
    logits = [-np.inf, np.inf, -50.0, 50.0, -40.0, 40.0, 0.0]
    means = [at_pixel(cam, 8 + 8 * i, 24 + (i % 2) * 6, 5.0 + 0.01 * i) for i in range(7)]
    return Setup(splats(means, np.full((7, 3), 0.25), logits=logits), cam)


def _coincident(precision: Precision, opacity: float) -> Callable[[], Setup]:
    """10,000 splats at one point with one shape: the transmittance underflows float32
    (opacity 0.02: T = 0.98^10000 ~ 1e-88) and a half-float target saturates."""
    def build() -> Setup:
        cam = front_camera()
        n = 10_000
        rng = np.random.default_rng(11)
        means = np.tile(at_pixel(cam, 32, 24, 5.0), (n, 1))
        scene = splats(means, np.full((n, 3), 0.4), opacities=np.full(n, opacity),
                       rgb=rng.uniform(0.0, 1.0, (n, 3)))
        return Setup(scene, cam, RenderSettings(precision=precision))
    return build


# ------------------------------------------------------------------------------ image size
def _image(size: int) -> Callable[[], Setup]:
    def build() -> Setup:
        cam = front_camera(width=size, height=size)
        uv = np.array([[0.5, 0.5], [0.3, 0.7], [0.0, 0.0], [1.0, 1.0], [0.9, 0.2]]) * size
        means = [at_pixel(cam, u, v, 5.0 + 0.1 * i) for i, (u, v) in enumerate(uv)]
        px = 3.0 * 5.0 / cam.fx                      # 3 px sigma at any image size
        return Setup(splats(means, np.full((5, 3), px), opacities=np.full(5, 0.7)), cam)
    return build


def _surfels_edge_on() -> Setup:
    """2DGS surfels exactly edge-on (normal perpendicular to the view), nearly edge-on
    (1e-3 and 1 degree), and one face-on, 45 degrees turned in the image plane."""
    cam = front_camera()
    turn = quat_axis_angle([0, 0, 1], 45.0)
    tilts = [90.0, 90.0 - 0.057, 89.0, 0.0]
    q = [quat_multiply(turn, quat_axis_angle([1, 0, 0], t)) for t in tilts]
    q.append(quat_axis_angle([0, 1, 0], 90.0))        # edge-on about the other axis
    means = [at_pixel(cam, 10 + 11 * i, 24, 5.0 + 0.1 * i) for i in range(5)]
    scene = splats(means, np.full((5, 2), 0.5), q, kind=SplatKind.SURFEL_2D)
    return Setup(scene, cam)


def _lens_splats(means, seed: int) -> Scene:
    rng = np.random.default_rng(seed)
    n = len(means)
    scales = rng.uniform(0.05, 0.4, (n, 3))
    scales[0] = [0.6, 6e-4, 6e-4]                      # a needle among them
    return splats(np.asarray(means, float), scales, rng.normal(size=(n, 4)),
                  opacities=rng.uniform(0.4, 0.9, n))


def _fisheye_90() -> Setup:
    """A 200-degree fisheye: splats exactly 90 degrees from the axis (view z = 0), just behind
    the camera plane (100 degrees) and on the axis, at several distances."""
    ang = np.radians([90.0, 90.0, 100.0, 95.0, 0.0, 45.0, 90.0])
    phi = np.radians([0.0, 90.0, 200.0, 300.0, 0.0, 135.0, 180.0])
    dist = np.array([3.0, 2.0, 4.0, 1.5, 5.0, 3.0, 0.8])
    means = dist[:, None] * np.c_[np.sin(ang) * np.cos(phi), np.sin(ang) * np.sin(phi), np.cos(ang)]
    return Setup(_lens_splats(means, 11), Camera.fisheye(WIDTH, WIDTH, 200.0))


def _equirect_poles() -> Setup:
    """A panorama with splats exactly at both poles (x = z = 0), beside them, and at the
    horizon; a pole splat must become one band across the image, drawn once."""
    means = [[0.0, -3.0, 0.0], [0.0, 2.0, 0.0], [0.05, -2.5, 0.02], [-0.3, 3.0, -0.2],
             [0.0, 0.0, 3.0], [3.0, 0.5, 0.0]]
    return Setup(_lens_splats(means, 12), Camera.equirectangular(2 * HEIGHT, HEIGHT))


def _equirect_seam() -> Setup:
    """A panorama with splats on the +-180 degree seam (x = 0, z < 0), just either side of it,
    and one large enough to reach far across it."""
    means = [[0.0, 0.0, -3.0], [0.02, 0.3, -2.0], [-0.02, -0.4, -2.5], [0.0, 0.0, -1.0],
             [0.4, 0.2, -3.0], [-0.4, -0.1, -3.5]]
    scene = _lens_splats(means, 13)
    return Setup(scene, Camera.equirectangular(2 * HEIGHT, HEIGHT))


#: The lens cases' quad bound: the reference's tile rectangle cuts splat tails up to ~1 px
#: short of 3 sigma on the right and bottom and the quad path draws them (docs/results/summary.md, alpha up to
#: 0.066 at one pixel); wide, faint splats squeezed by a fisheye or stretched near a pole meet
#: such a tile edge more often (docs/camera-models.md).
_LENS_BOUNDS = Bounds(quad=0.07, why="lens: the tile-rectangle tail, up to alpha 0.066 at one pixel")
_NO_PANORAMA_TILES = {"tile": "the tile renderer has no seam copies and refuses panoramas"}


_HALF_SATURATION = (
    "in RGBA16F the accumulated alpha stalls at 1 - 2^-10 (measured on llvmpipe; half floats "
    "cannot approach 1 in steps that small), so the transmittance never reaches the 1e-4 stop: "
    "each later splat still adds c alpha 2^-10, and over 10,000 layers a channel climbs until "
    "its own half-float step swallows that (measured: red 0.50 where the truth is 0.17).  "
    "Tried and not kept: keeping T, not A, in the alpha channel (colour factor DST_ALPHA, alpha "
    "factor ONE_MINUS_SRC_ALPHA) cut this case to 0.10 (colour increments now fall below the "
    "half-float step instead) but made real scenes worse (donut_sh0 at 512x384: 56.8 -> 43.7 dB, "
    "guitar 66 -> 60.6 dB), so the design card's blend stays.  A half-float target cannot hold "
    "10,000 layers either way; RGBA32F (the default) is unaffected")


CASES: tuple[StressCase, ...] = (
    StressCase("scales", "isotropic scales 1e-8 .. 1e4 in one view", _scales),
    StressCase("aniso_face_on", "needle and pancake 1e6:1, face-on", _aniso(0.0)),
    StressCase("aniso_45", "needle and pancake 1e6:1, 45 degrees out of the image plane", _aniso(45.0)),
    StressCase("aniso_edge_on", "needle and pancake 1e6:1, edge-on", _aniso(90.0)),
    StressCase("det_nonpositive", "2D covariance whose float32 det cancels to <= 0", _det_nonpositive),
    StressCase("quat_norms", "unnormalised quaternions, norms 1e-6 .. 1e6", _quat_norms),
    StressCase("zero_quats", "zero and sub-1e-12 quaternions (skipped)", _zero_quats),
    StressCase("near_plane", "splats crossing the near plane, on it, at z = 0, behind", _near_plane),
    StressCase("near_tiny", "near plane 1e-8, splats just past it (cov2d ~ 1e20 px^2)", _near_tiny),
    StressCase("border", "centres exactly on the image border and tile boundaries", _border),
    StressCase("offscreen_huge", "far off-screen centres with huge extents", _offscreen_huge),
    StressCase("far_1e5", "scene 1e5 from the origin, camera near it", _far_origin(1e5)),
    StressCase("far_1e6", "scene 1e6 from the origin, camera near it", _far_origin(1e6)),
    StressCase("far_1e7", "scene 1e7 from the origin, camera near it", _far_origin(1e7)),
    StressCase("fov_0.1", "vertical field of view 0.1 degrees", _fov(0.1)),
    StressCase("fov_170", "vertical field of view 170 degrees", _fov(170.0)),
    StressCase("ortho_tiny_zoom", "orthographic, 1e-3 px per unit", _ortho(1e-3)),
    StressCase("ortho_huge_zoom", "orthographic, 1e6 px per unit", _ortho(1e6)),
    StressCase("opacity_extremes", "opacity 0 and 1 (logits -+inf), logits +-50, +-40", _opacity_extremes),
    StressCase("coincident_10k", "10,000 coincident splats, opacity 0.02 (T underflow)",
               _coincident(Precision.RGBA32F, 0.02)),
    StressCase("coincident_10k_half", "10,000 coincident splats, opacity 0.5, RGBA16F quad target",
               _coincident(Precision.RGBA16F, 0.5), known={"quad": _HALF_SATURATION}),
    StressCase("image_1x1", "a 1 x 1 image", _image(1)),
    StressCase("image_8192", "an 8192 x 8192 image, sparse scene", _image(8192), slow=True),
    StressCase("surfels_edge_on", "2DGS surfels edge-on and nearly edge-on", _surfels_edge_on,
               unsupported={"cpu": "the CPU renderer draws 3DGS splats only"}),
    StressCase("fisheye_90", "200-degree fisheye: splats at 90 degrees from the axis and behind "
               "the camera plane", _fisheye_90, _LENS_BOUNDS),
    StressCase("equirect_poles", "panorama: splats at and beside both poles", _equirect_poles,
               _LENS_BOUNDS, unsupported=_NO_PANORAMA_TILES),
    StressCase("equirect_seam", "panorama: splats on and across the +-180 degree seam",
               _equirect_seam, _LENS_BOUNDS, unsupported=_NO_PANORAMA_TILES),
)


def case_by_name(name: str) -> StressCase:
    """The case called ``name`` (KeyError with the list of names otherwise)."""
    for case in CASES:
        if case.name == name:
            return case
    raise KeyError(f"no stress case {name!r}; cases: {', '.join(c.name for c in CASES)}")
