"""The view: everything one frame needs from its camera, computed once and handed to every stage.

Each stage (the order stage's cull and sort, the quad path's pre-pass and draw, the tile
renderer, the NumPy reference, the level-of-detail cut) takes a :class:`View`, never the raw
camera, so the camera is interpreted in one place:

- the scene transform folded into the camera (:func:`apply_transform`: scene-to-camera);
- the scene's anchor folded into the translation in float64 (:func:`anchored_camera`), since
  every path projects ``means - anchor``;
- the near plane (``settings.near`` or the scene-relative default) and its float32 and float64
  thresholds (:func:`near_threshold`);
- the model's shader ``#define`` switches and the values of every camera uniform;
- its :class:`Frustum`: which cull the order stage, the level-of-detail cut and the CPU
  renderer use (the model's :class:`~splatgl.cameras.model.CullKind`) and the planes it tests.
  No other module computes frustum planes.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from ..constants import LOW_PASS
from ..output.under import DepthKind, UnderImage, UnderLayer
from .camera import Camera
from .model import CameraModel, CullKind

if TYPE_CHECKING:
    from ..scene.splats import Scene
    from ..scene.settings import RenderSettings
    from ..scene.transform import SceneTransform


def apply_transform(camera: Camera, model: "SceneTransform | None") -> Camera:
    """The camera seen from the scene's own frame: matrix ``world_to_camera @ model.matrix``."""
    if model is None or model.is_identity:
        return camera
    return camera.with_pose(camera.world_to_camera @ model.matrix)


def anchored_camera(camera: Camera, anchor: np.ndarray) -> Camera:
    """``camera`` for points given relative to ``anchor`` (world, float64 (3,)).

    Guard (stress cases far_1e5 .. far_1e7, ortho_huge_zoom): float32 ``R p + t`` on raw
    coordinates 1e7 from the origin keeps about one unit of precision (the scene shredded,
    max error 0.79).  Every renderer therefore works on ``p - anchor`` (small numbers) with the
    anchor folded into the translation in float64: ``t' = R anchor + t``.
    """
    shift = np.eye(4)
    shift[:3, 3] = np.asarray(anchor, np.float64)
    return camera.with_pose(camera.world_to_camera @ shift)


def draft_low_pass(full: Camera, drawn: Camera) -> float | None:
    """:attr:`View.low_pass` for ``drawn``, a draft of ``full`` at fewer pixels (the same view,
    resized): LOW_PASS times the draft's pixels per full-size pixel (``fx`` and ``fy`` ratios),
    so each splat covers what it covers in the full-size frame; None where nothing is scaled.

    Measured on the shared scenes at 1280x720 (the flight's views, against the exact frame):
    drafts at scales 0.2-0.5 with the full LOW_PASS in their own pixels were blurred and grown
    by it (0.3 / s^2 full-size px^2), 5-8 dB worse than with this (donut at 0.3: 25.4 against
    33.2 dB; biker 30.5 against 36.4).
    """
    ratio = (drawn.fx / full.fx) * (drawn.fy / full.fy)
    return None if ratio == 1.0 else LOW_PASS * ratio


def near_threshold(near: float, dtype) -> np.floating:
    """The near plane as a ``dtype`` number that culls exactly the z values float64 culls.

    Guard (stress case near_plane): ``float32(0.1)`` rounds up to 0.10000000149, so a splat whose
    stored z is that very value was culled in float32 (z <= near) but kept in float64 (max error
    0.41).  Rounding the plane down instead makes ``z > near`` agree in both precisions.
    """
    dt = np.dtype(dtype).type
    value = dt(near)
    if float(value) > near:
        value = np.nextafter(value, dt(-np.inf))
    return value


@dataclass(frozen=True)
class Frustum:
    """What a camera's cull tests splats against (:func:`frustum_of`).

    Attributes:
        kind: the model's cull (:class:`~splatgl.cameras.model.CullKind`); the order stage's
            table :data:`splatgl.order.stage.CULLS` maps it to the cull that runs.
        camera: the camera whose image edges bound what is drawn: the camera itself, or for a
            model with its own cull frustum (lens distortion,
            :meth:`~splatgl.cameras.model.CameraModel.cull_frustum`) a pinhole with its pose
            whose side planes hold every ray the image sees.
        peak: whether the peak-alpha bound may cull (it holds for pinhole images only).
        edges: per image axis (x, y) ``(f, lo, hi)``: the focal length and the image's edges,
            ``-c / f`` and ``(size - c) / f``: slopes ``x / z`` of the four side planes through
            the camera centre (FRUSTUM), or camera-space coordinates of the box (BOX).
        angle_limit: SPHERE: the largest angle from the optical axis kept (radians), or None.
    """

    kind: CullKind
    camera: Camera
    peak: bool
    edges: tuple[tuple[float, float, float], tuple[float, float, float]]
    angle_limit: float | None = None

    @property
    def sides(self) -> tuple[tuple[float, float, float, float], ...]:
        """Per image axis (x, y) the side planes ``v = s z`` (FRUSTUM) as ``(lo, sqrt(1 + lo^2),
        hi, sqrt(1 + hi^2))``: each slope and the length of its plane's normal ``(1, -s)``, by
        which a point's ``v - s z`` is divided to give its distance from the plane.  What every
        plane cull (the order's, the level-of-detail cut's, the quad path's shader) reads."""
        return tuple((lo, float(np.sqrt(1.0 + lo * lo)), hi, float(np.sqrt(1.0 + hi * hi)))
                     for _f, lo, hi in self.edges)

    @property
    def pinhole(self) -> bool:
        """Whether the image is a pinhole's (its own four side planes, the peak bound): what the
        CPU renderer's compiled pinhole projection draws."""
        return self.kind is CullKind.FRUSTUM and self.peak


def frustum_of(camera: Camera) -> Frustum:
    """The :class:`Frustum` of ``camera`` (anchored or not: the planes pass through its centre)."""
    own = camera.model.cull_frustum(camera)
    bound = camera if own is None else own
    edges = tuple((f, -c / f, (size - c) / f) for f, c, size in
                  ((bound.fx, bound.cx, bound.width), (bound.fy, bound.cy, bound.height)))
    kind = camera.model.cull
    limit = camera.model.angle_limit(camera) if kind is CullKind.SPHERE else None
    return Frustum(kind, bound, own is None, edges, limit)


@dataclass(frozen=True, eq=False)
class View:
    """One frame's camera, interpreted once.

    Attributes:
        camera: the camera in the scene's own frame (the scene transform folded in), not
            anchored: what the CPU's float64 maths and the depth layer use.
        near: the near plane distance (world units of the scene's frame).
        anchor: (3,) float64 point subtracted from every mean before projecting (the scene's
            :attr:`~splatgl.scene.splats.Scene.anchor`; zeros for raw means).
        low_pass: the screen-space dilation (px^2) the GPU paths add to each splat's 2D
            covariance, or None: ``constants.LOW_PASS``, as every exact frame.  A draft drawn
            at a fraction s of its window's width and height (:func:`draft_low_pass`) passes
            LOW_PASS s^2, so its splats keep the full-size frame's footprint.  It changes
            neither the order nor the cull (whose bounds assume the larger LOW_PASS, so they
            stay conservative).
    """

    camera: Camera
    near: float
    anchor: np.ndarray = field(default_factory=lambda: np.zeros(3))
    low_pass: float | None = None

    @classmethod
    def of(cls, camera: Camera, settings: "RenderSettings", scene: "Scene") -> "View":
        """The view of ``camera`` (world frame) for ``scene`` under ``settings``: the model
        transform, the scene-relative near plane and the scene's anchor."""
        from ..scene.settings import resolve_near

        return cls(apply_transform(camera, settings.transform), resolve_near(settings, scene.robust_radius),
                   np.asarray(scene.anchor, np.float64))

    # ---------------------------------------------------------------- derived once per frame
    @property
    def model(self) -> CameraModel:
        return self.camera.model

    @property
    def width(self) -> int:
        return self.camera.width

    @property
    def height(self) -> int:
        return self.camera.height

    @cached_property
    def anchored(self) -> Camera:
        """The camera for anchored points (``p - anchor``): what the GPU and the order stage use."""
        return anchored_camera(self.camera, self.anchor)

    @cached_property
    def frustum(self) -> Frustum:
        """The anchored camera's :class:`Frustum`: the cull the order stages run and its planes."""
        return frustum_of(self.anchored)

    @cached_property
    def scale(self) -> float:
        """The uniform scale folded into the camera (a scene transform's; 1 otherwise)."""
        return self.camera.scale

    @cached_property
    def near32(self) -> np.float32:
        """The near plane as float32, rounded so that it culls what float64 culls."""
        return near_threshold(self.near, np.float32)

    def near_in(self, dtype) -> np.floating:
        """The near plane in ``dtype`` (:func:`near_threshold`)."""
        return near_threshold(self.near, dtype)

    @cached_property
    def key(self) -> tuple:
        """What decides the order of the splats: equal keys, equal order (the quad path reuses
        the last order when the key repeats)."""
        c = self.camera
        return (c.world_to_camera.tobytes(), c.fx, c.fy, c.cx, c.cy, c.width, c.height, c.model,
                self.near, self.anchor.tobytes())

    @cached_property
    def defines(self) -> dict[str, object]:
        """The model's shader ``#define`` switches (and VIEW_LOW_PASS with :attr:`low_pass`)."""
        out = self.model.defines()
        if self.low_pass is not None:
            out = {**out, "VIEW_LOW_PASS": 1}
        return out

    @cached_property
    def uniforms(self) -> dict[str, object]:
        """Values of every uniform of ``shaders/lib/camera.glsl`` and the model's piece, for
        anchored means (float32 where the shader holds float32)."""
        cam = self.anchored
        tx, ty = cam.tan_half_fov
        return {
            "u_view_rot": tuple(cam.rotation.astype(np.float32).T.ravel()),  # column-major
            "u_view_trans": tuple(cam.translation.astype(np.float32)),
            "u_cam_center": tuple(cam.center.astype(np.float32)),
            "u_intrinsics": (cam.fx, cam.fy, cam.cx, cam.cy),
            "u_viewport": (float(cam.width), float(cam.height)),
            "u_tan_fov": (tx, ty),
            "u_near": float(self.near32),
            **({} if self.low_pass is None else {"u_low_pass": float(self.low_pass)}),
            **self.model.uniforms(cam),
        }

    def geometry(self, under: UnderImage) -> UnderLayer:
        """``under`` (geometry rendered from this view's camera) as the renderers take it: its
        size checked, its depth in the camera model's own metric
        (:meth:`~splatgl.cameras.model.CameraModel.pixel_depth`)."""
        under.check_size(self.width, self.height)
        along_ray = under.kind is DepthKind.DISTANCE
        return UnderLayer(under.rgb, under.alpha,
                          self.model.pixel_depth(under.depth, along_ray, self.camera))

    def set_uniforms(self, prog) -> None:
        """Write the uniforms ``prog`` (a moderngl program) uses."""
        for name, value in self.uniforms.items():
            if name in prog:
                prog[name].value = value
