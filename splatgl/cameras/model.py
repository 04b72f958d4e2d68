"""What a camera model is: one type that carries everything a projection changes.

EWA splatting linearises the projection at each splat's centre, so a camera model changes only
where a centre lands (:meth:`CameraModel.project`) and the 2x3 Jacobian of that map
(:meth:`CameraModel.jacobian`); the 2D covariance, conic, extent and blending downstream are the
same for every model.  Around those two a model also says:

- which splats it can see (:meth:`~CameraModel.visible`, the float64 twin of the shader's
  ``in_view``) and how the order stage culls for it (:attr:`~CameraModel.cull`, one of a few
  strategies the order stage implements);
- the depth that orders and layers its splats (:meth:`~CameraModel.depth`);
- its shader piece (``shaders/cameras/<glsl>.glsl``: ``project_mean``, ``jacobian``,
  ``in_view``, ``view_depth``), its ``#define`` switches and its uniform values;
- whether it draws 2DGS surfels (:meth:`~CameraModel.check_surfels`; what each renderer draws:
  :mod:`splatgl.renderers.registry`);
- how it is made from a field of view (:meth:`~CameraModel.intrinsics`, the CLI's ``--projection``)
  and how its parameters read and write in camera files: splatgl's camera JSON
  (:meth:`~CameraModel.to_json`), COLMAP's ``cameras.txt``/``.bin`` (:attr:`~CameraModel.colmap_names`,
  :meth:`~CameraModel.from_colmap`, :meth:`~CameraModel.to_colmap`) and ``transforms.json``
  (:attr:`~CameraModel.transforms_names`, :meth:`~CameraModel.from_transforms`,
  :meth:`~CameraModel.to_transforms`).  The registry gives each COLMAP or transforms.json name
  to the last registered model that claims it, so a later model can take a name over.

A model is a frozen dataclass whose fields are its own parameters (a fisheye's k1..k4, a
panorama's stereo eye offset); intrinsics (fx, fy, cx, cy) and the pose stay on
:class:`~splatgl.cameras.camera.Camera`.  :mod:`splatgl.cameras.registry` lists the models by
name.  Adding a model means one module here, one shader piece and one registry line.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from ..errors import CameraError

if TYPE_CHECKING:
    from .camera import Camera


class CullKind(enum.Enum):
    """The order stage's cull strategies; a model picks one.  A view's
    :attr:`~splatgl.cameras.view.View.frustum` carries it with the planes, and the one table
    :data:`splatgl.order.stage.CULLS` maps it to the cull the scene order, the level-of-detail
    cut and order, and the CPU renderer use.

    FRUSTUM: view z beyond the near plane and the splat's reach inside the four side planes
        through the camera centre (the pinhole's pyramid), plus the peak-alpha bound.
    BOX: parallel rays: view z beyond the near plane and the reach inside an axis-aligned box.
    SPHERE: projections by angle, which see behind the camera plane: distance beyond the near
        plane, a model's angle limit (:meth:`CameraModel.angle_limit`) and its seam copies
        (:meth:`CameraModel.seam_period`); splats order by distance.
    """

    FRUSTUM = "frustum"
    BOX = "box"
    SPHERE = "sphere"


@dataclass(frozen=True)
class CameraModel:
    """Base of the camera models (see the module doc)."""

    #: The model's name: the CLI's ``--projection`` value and the camera files' "projection".
    name: ClassVar[str] = ""
    #: Its shader piece, ``shaders/cameras/<glsl>.glsl`` (a model that does not set it: its name).
    glsl: ClassVar[str] = ""
    #: How the order stage culls for it.
    cull: ClassVar[CullKind] = CullKind.FRUSTUM
    #: Whether every pixel's ray has the same direction (orthographic): 2DGS surfels then
    #: intersect parallel rays.
    parallel_rays: ClassVar[bool] = False
    #: Whether 2DGS surfels can be drawn (their ray-plane intersection needs a pinhole matrix).
    draws_surfels: ClassVar[bool] = True
    #: Why ``--fov`` does not apply to this model ("" where it does).
    no_fov: ClassVar[str] = ""
    #: Whether re-projecting a camera to this model keeps its intrinsics (orthographic: fx, fy
    #: read as pixels per world unit); otherwise only the pose is kept and the model makes its own.
    keeps_intrinsics: ClassVar[bool] = False
    #: Width / height of an image of this model when only one side is given (None: the
    #: camera's own aspect; a full panorama: 2).
    aspect: ClassVar[float | None] = None
    #: Whether a camera file may leave out fx, fy, cx, cy (the model's own intrinsics at the
    #: file's size: a full panorama).
    intrinsics_optional: ClassVar[bool] = False
    #: A one-line description for ``--help``.
    summary: ClassVar[str] = ""
    #: COLMAP camera model names (``cameras.txt``/``.bin``) that :meth:`from_colmap` reads.
    colmap_names: ClassVar[tuple[str, ...]] = ()
    #: ``transforms.json`` ``camera_model`` values that :meth:`from_transforms` reads.
    transforms_names: ClassVar[tuple[str, ...]] = ()
    #: The ``transforms.json`` number fields (besides the intrinsics) it reads, e.g. ``k1``.
    transforms_fields: ClassVar[tuple[str, ...]] = ()
    #: Its own fields of the single-camera JSON (:meth:`from_json`), e.g. ``distortion``: a
    #: camera file giving one of another model's is refused (it would be ignored).
    json_fields: ClassVar[tuple[str, ...]] = ()

    def __init_subclass__(cls, **kwargs) -> None:
        super().__init_subclass__(**kwargs)
        if "glsl" not in vars(cls):
            cls.glsl = cls.name

    # ------------------------------------------------------------------ float64/float32 twins
    def project(self, p_cam: np.ndarray, camera: "Camera") -> np.ndarray:
        """(N, 3) camera-space points -> (N, 2) image coordinates (u, v), in ``p_cam``'s dtype."""
        raise NotImplementedError

    def jacobian(self, p_cam: np.ndarray, camera: "Camera") -> np.ndarray:
        """(N, 2, 3) Jacobian of :meth:`project` at ``p_cam`` (EWA's linearisation)."""
        raise NotImplementedError

    def depth(self, p_cam: np.ndarray) -> np.ndarray:
        """(N,) the depth that sorts splats and fills the depth layer: view z by default."""
        return p_cam[:, 2]

    @property
    def depth_is_distance(self) -> bool:
        """Whether :meth:`depth` (the sort key, the depth layers) is the distance from the
        camera (the SPHERE models: fisheye, panorama) rather than view-space z."""
        return self.cull is CullKind.SPHERE

    def pixel_depth(self, depth: np.ndarray, along_ray: bool, camera: "Camera") -> np.ndarray:
        """(H, W) depths of what this camera's pixels see, given as view-space z (``along_ray``
        False) or as the distance along each pixel's ray (True), in this model's own depth
        metric (:meth:`depth`; geometry composited under splats, :mod:`splatgl.output.under`).
        Non-finite values (no geometry) stay +inf.

        Perspective: ``z = distance / |((u - cx) / fx, (v - cy) / fy, 1)|`` at the pixel centre;
        orthographic: rays start on the camera plane, so both are z; fisheye and panorama
        cameras order splats by distance, and a view-space z is refused (it does not name one
        point of a ray that turns behind the camera)."""
        d = np.where(np.isfinite(depth), np.asarray(depth, np.float64), np.inf)
        if self.depth_is_distance:
            if not along_ray:
                raise CameraError(f"{self.name} cameras sort splats by distance; give the geometry's "
                                  "depth as distance along the ray, not view-space z")
            return d.astype(np.float32)
        if self.parallel_rays or not along_ray:
            return d.astype(np.float32)
        h, w = d.shape
        x = (np.arange(w) + 0.5 - camera.cx) / camera.fx
        y = (np.arange(h) + 0.5 - camera.cy) / camera.fy
        length = np.sqrt(x[None, :] ** 2 + y[:, None] ** 2 + 1.0)
        return (d / length).astype(np.float32)

    def visible(self, p_cam: np.ndarray, camera: "Camera", near) -> np.ndarray:
        """(N,) bool: centres the model draws (the shader's ``in_view``): view z beyond ``near``."""
        return p_cam[:, 2] > near

    def angle_limit(self, camera: "Camera") -> float | None:
        """SPHERE models: the largest angle from the optical axis kept (radians), or None."""
        return None

    def seam_period(self, camera: "Camera") -> float | None:
        """SPHERE models whose image wraps around: pixels per full turn, else None."""
        return None

    def cull_frustum(self, camera: "Camera") -> "Camera | None":
        """FRUSTUM models whose image is not a pinhole's (lens distortion): a pinhole camera
        with ``camera``'s pose whose four side planes hold every ray the image sees.  The order
        stage then culls against those planes without the peak-alpha bound (which holds for
        pinhole images only).  None (the default): ``camera``'s own frustum, with the bound."""
        return None

    def eye_pair(self, camera: "Camera", half_ipd: float) -> "tuple[Camera, Camera] | None":
        """(left, right) eye cameras of a stereo rig where the model has its own rig, else
        None (the rig then shifts the pose by -+``half_ipd`` along camera x)."""
        return None

    # ------------------------------------------------------------------ the GPU side
    def defines(self) -> dict[str, object]:
        """``#define`` switches of the shaders: the piece to include and the model's own."""
        return {"CAMERA_MODEL": self.glsl}

    def uniforms(self, camera: "Camera") -> dict[str, object]:
        """Values of the model's own uniforms (declared in its shader piece)."""
        return {}

    # ------------------------------------------------------------------ use
    def check_surfels(self, surfels: bool) -> None:
        """Raise :class:`~splatgl.errors.CameraError` for a scene of 2DGS surfels (``surfels``)
        where this model draws none, in any renderer."""
        if surfels and not self.draws_surfels:
            raise CameraError(f"{self.name} cameras render 3DGS scenes only; this scene holds 2DGS "
                              "surfels (use a perspective or orthographic camera)")

    @classmethod
    def intrinsics(cls, width: int, height: int, fov_degrees: float | None,
                   like: "Camera | None" = None) -> tuple[float, float, float, float, "CameraModel"]:
        """``(fx, fy, cx, cy, model)`` of a camera of this model at this size (the CLI's
        ``--projection`` and ``--fov``; :meth:`splatgl.cameras.camera.Camera.of_model`).

        ``fov_degrees`` None takes the model's default; ``like`` is the camera being
        re-projected, for models that keep something of it (an orthographic camera keeps its
        scale, a perspective one its intrinsics when no field of view is given).
        """
        raise NotImplementedError

    @classmethod
    def fov_range(cls) -> tuple[float, float, bool] | None:
        """``(low, high, high_included)`` of ``--fov`` in degrees, or None where it does not apply."""
        return None

    # ------------------------------------------------------------------ files
    def to_json(self) -> dict[str, object]:
        """The model's own fields of the single-camera JSON (besides ``"projection"``)."""
        return {}

    @classmethod
    def from_json(cls, obj: dict, path, where: str = "") -> "CameraModel":
        """The model from a single-camera JSON object's own fields (errors name ``path`` and
        ``where``, as :mod:`splatgl.cameras.json_fields` does)."""
        return cls()

    @classmethod
    def from_colmap(cls, name: str, params: tuple[float, ...]
                    ) -> tuple[float, float, float, float, "CameraModel"]:
        """``(fx, fy, cx, cy, model)`` of a COLMAP camera of model ``name`` (one of
        :attr:`colmap_names`) with its parameters (their count already checked).  Raises
        :class:`~splatgl.errors.CameraError` (the reader prefixes the file and camera) for
        values this model refuses."""
        raise NotImplementedError

    def to_colmap(self, camera: "Camera") -> tuple[str, tuple[float, ...]]:
        """``(COLMAP model name, parameters)`` of ``camera`` (of this model)."""
        raise CameraError(f"COLMAP has no camera model for {self.name} cameras")

    @classmethod
    def from_transforms(cls, name: str, fields: dict[str, float | None]) -> "CameraModel":
        """The model of a ``transforms.json`` frame whose ``camera_model`` is ``name`` (one of
        :attr:`transforms_names`); ``fields`` maps each of :attr:`transforms_fields` to its value
        (the frame's, else the file's) or None.  Raises CameraError (the reader prefixes the
        file and frame) for values this model refuses."""
        raise NotImplementedError

    def to_transforms(self) -> dict[str, object]:
        """The ``transforms.json`` fields of this model: ``camera_model`` and its own fields."""
        raise CameraError(f"transforms.json has no camera model for {self.name} cameras")


@dataclass(frozen=True)
class LensDistortion(CameraModel):
    """Base of the models with lens distortion coefficients (OpenCV's, the fisheye's): a camera
    file gives them as ``distortion``, and 2DGS surfels are not drawn (their ray-plane
    intersection needs an undistorted pinhole matrix)."""

    draws_surfels: ClassVar[bool] = False
    json_fields: ClassVar[tuple[str, ...]] = ("distortion",)


def colmap_intrinsics(params: tuple[float, ...], focals: int) -> tuple[float, float, float, float]:
    """``(fx, fy, cx, cy)`` from the leading COLMAP parameters: ``f cx cy`` (``focals`` 1) or
    ``fx fy cx cy`` (``focals`` 2)."""
    if focals == 1:
        return params[0], params[0], params[1], params[2]
    return params[0], params[1], params[2], params[3]
