"""The OpenCV camera: a pinhole with OpenCV's radial-tangential lens distortion.

COLMAP's SIMPLE_RADIAL ``(f, cx, cy, k1)``, RADIAL ``(f, cx, cy, k1, k2)``, OPENCV ``(fx, fy,
cx, cy, k1, k2, p1, p2)`` and FULL_OPENCV ``(fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, k5, k6)``,
nerfstudio's ``transforms.json`` OPENCV (``k1 k2 k3 p1 p2``) and ``cv2.projectPoints`` with
``distCoeffs = (k1, k2, p1, p2, k3, k4, k5, k6)`` are this model.  Shader piece:
``shaders/cameras/opencv.glsl`` (same names).  Camera space, OpenCV axes; with ``a = x / z``,
``b = y / z``, ``r^2 = a^2 + b^2``:

``R(r^2) = (1 + k1 r^2 + k2 r^4 + k3 r^6) / (1 + k4 r^2 + k5 r^4 + k6 r^6)``,
``a_d = a R + 2 p1 a b + p2 (r^2 + 2 a^2)``, ``b_d = b R + p1 (r^2 + 2 b^2) + 2 p2 a b``,
``u = fx a_d + cx``, ``v = fy b_d + cy``.

EWA's Jacobian by the chain rule through the pinhole's ``(a, b)``: ``J = diag(fx, fy) D P`` with
``P = [[1/z, 0, -a/z], [0, 1/z, -b/z]]`` and the distortion's symmetric 2x2 ``D``
(``g = dR / d r^2``):
``D = [[R + 2 a^2 g + 2 p1 b + 6 p2 a, c], [c, R + 2 b^2 g + 6 p1 b + 2 p2 a]]``,
``c = 2 a b g + 2 p1 a + 2 p2 b``.  Both are taken at ``(a, b)`` clamped to the image's tangent
bounds widened by (JACOBIAN_CLAMP - 1) / 2 of their width on each side
(:meth:`OpenCV.jacobian_box`; a centred pinhole's clamp).  Clamping D too matters: far outside
the image D grows fast (pincushion), and the unclamped first-order footprint of a splat
thousands of pixels away reached into the image.

Strong barrel distortion folds: ``r R(r^2)`` grows up to a largest radius, then falls, and
points beyond it would land back inside the image (``cv2.projectPoints`` puts them there).  Such
a lens cannot see them, so centres beyond that radius (:func:`fold_radius`; the radial part
only) are not drawn.  The order stage culls against a pinhole frustum that holds every ray the
distorted image sees (:meth:`OpenCV.cull_frustum`; the peak-alpha bound, which holds for
pinhole images only, is off).  Zero distortion read from a COLMAP or transforms.json file is a
plain pinhole camera.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from functools import lru_cache
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from ..constants import JACOBIAN_CLAMP
from ..errors import CameraError
from .model import LensDistortion, colmap_intrinsics
from .pinhole import DEFAULT_FOV, Pinhole

if TYPE_CHECKING:
    from .camera import Camera

#: Normalised radius (tangent of the angle off the axis, 89.4 degrees) up to which the radial
#: map is searched for a fold; also the bound of the cull frustum where the image reaches the fold.
R_SCAN = 100.0
#: Pixels the image border is widened by before it is undistorted to the cull frustum (covers
#: the dilation's reach and the curvature of the map across a splat's first-order footprint).
CULL_MARGIN_PX = 16.0
#: COLMAP model -> (focal count, its distortion parameters in order).
COLMAP_MODELS = {"SIMPLE_RADIAL": (1, ("k1",)), "RADIAL": (1, ("k1", "k2")),
                 "OPENCV": (2, ("k1", "k2", "p1", "p2")),
                 "FULL_OPENCV": (2, ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"))}


def radial(r2: np.ndarray, m: "OpenCV") -> tuple[np.ndarray, np.ndarray]:
    """``(R, dR / d r^2)`` of the rational radial factor at squared radii ``r2`` (its dtype)."""
    dt = r2.dtype.type
    k1, k2, k3, k4, k5, k6 = (dt(v) for v in (m.k1, m.k2, m.k3, m.k4, m.k5, m.k6))
    num = dt(1) + r2 * (k1 + r2 * (k2 + r2 * k3))
    den = dt(1) + r2 * (k4 + r2 * (k5 + r2 * k6))
    dnum = k1 + r2 * (dt(2) * k2 + dt(3) * r2 * k3)
    dden = k4 + r2 * (dt(2) * k5 + dt(3) * r2 * k6)
    return num / den, (dnum * den - num * dden) / (den * den)


def distort(n: np.ndarray, m: "OpenCV") -> np.ndarray:
    """(N, 2) distorted normalised coordinates ``(a_d, b_d)`` of (N, 2) ``(a, b)``."""
    dt = n.dtype.type
    a, b = n[:, 0], n[:, 1]
    r2 = a * a + b * b
    rad, _ = radial(r2, m)
    p1, p2 = dt(m.p1), dt(m.p2)
    return np.stack([a * rad + dt(2) * p1 * a * b + p2 * (r2 + dt(2) * a * a),
                     b * rad + p1 * (r2 + dt(2) * b * b) + dt(2) * p2 * a * b], -1)


def distort_jacobian(n: np.ndarray, m: "OpenCV") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(D00, D01 = D10, D11)`` (N,) each: the symmetric Jacobian of :func:`distort` at ``n``."""
    dt = n.dtype.type
    a, b = n[:, 0], n[:, 1]
    rad, g = radial(a * a + b * b, m)
    p1, p2, two = dt(m.p1), dt(m.p2), dt(2)
    off = two * a * b * g + two * p1 * a + two * p2 * b
    return (rad + two * a * a * g + two * p1 * b + dt(6) * p2 * a, off,
            rad + two * b * b * g + dt(6) * p1 * b + two * p2 * a)


@lru_cache(maxsize=64)
def fold_radius(m: "OpenCV") -> float:
    """The normalised radius where the radial map ``r R(r^2)`` stops growing (or its
    denominator reaches 0), found on a 1e-3 grid up to :data:`R_SCAN` and refined by bisection;
    ``inf`` where it grows all the way."""
    def bad(r: np.ndarray) -> np.ndarray:
        r2 = r * r
        rad, g = radial(r2, m)
        den = 1.0 + r2 * (m.k4 + r2 * (m.k5 + r2 * m.k6))
        return ~((rad + 2.0 * r2 * g > 0.0) & (den > 0.0))

    grid = np.linspace(0.0, R_SCAN, 100001)
    hits = np.flatnonzero(bad(grid))
    if hits.size == 0:
        return math.inf
    lo, hi = float(grid[max(hits[0] - 1, 0)]), float(grid[hits[0]])
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if bad(np.array([mid]))[0] else (mid, hi)
    return lo


def undistort(d: np.ndarray, m: "OpenCV", iterations: int = 50) -> tuple[np.ndarray, np.ndarray]:
    """Newton's inverse of :func:`distort` on (N, 2) float64 ``d``, started at ``d``:
    ``(n (N, 2), ok (N,))``, ``ok`` where it converged (residual below 1e-12) inside the fold
    radius."""
    n = d.copy()
    for _ in range(iterations):
        res = distort(n, m) - d
        d00, d01, d11 = distort_jacobian(n, m)
        det = d00 * d11 - d01 * d01
        with np.errstate(divide="ignore", invalid="ignore"):
            step = np.stack([(d11 * res[:, 0] - d01 * res[:, 1]) / det,
                             (d00 * res[:, 1] - d01 * res[:, 0]) / det], -1)
        n = n - np.where(np.isfinite(step), step, 0.0)
    res = np.abs(distort(n, m) - d).max(axis=1)
    return n, (res < 1e-12) & (np.einsum("ni,ni->n", n, n) < fold_radius(m) ** 2)


@lru_cache(maxsize=64)
def tangent_bounds(m: "OpenCV", fx: float, fy: float, cx: float, cy: float, width: int,
                   height: int, margin: float) -> tuple[float, float, float, float]:
    """``(a_lo, a_hi, b_lo, b_hi)``: the box of normalised ``(x/z, y/z)`` holding every point
    inside the fold radius whose distorted pixel lies in the image widened by ``margin`` px.

    The border of the widened image (every 0.5 px) is undistorted (:func:`undistort`); where
    all of it has a preimage the box of those preimages holds the whole region (the map is one
    to one inside the fold).  Where some of it has none (the image reaches past the fold), the
    box of the fold circle (radius at most :data:`R_SCAN`) is added.
    """
    u0, u1, v0, v1 = -margin, width + margin, -margin, height + margin
    nu, nv = int(2 * (u1 - u0)) + 1, int(2 * (v1 - v0)) + 1
    us, vs = np.linspace(u0, u1, nu), np.linspace(v0, v1, nv)
    border = np.concatenate([np.stack([us, np.full(nu, v0)], -1), np.stack([us, np.full(nu, v1)], -1),
                             np.stack([np.full(nv, u0), vs], -1), np.stack([np.full(nv, u1), vs], -1)])
    d = (border - [cx, cy]) / [fx, fy]
    n, ok = undistort(d, m)
    lo, hi = (n[ok].min(axis=0), n[ok].max(axis=0)) if ok.any() else (np.zeros(2), np.zeros(2))
    if not ok.all():
        r = min(fold_radius(m), R_SCAN)
        lo, hi = np.minimum(lo, -r), np.maximum(hi, r)
    return float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1])


#: The lengths of OpenCV's ``distCoeffs`` a camera file may give (OpenCV's own: 4, 5, 8, 12, 14).
DISTORTION_COUNTS = (4, 5, 8, 12, 14)
#: OpenCV's terms after k6 (thin prism, tilted sensor): accepted only as 0.
EXTRA_TERMS = ("s1", "s2", "s3", "s4", "tauX", "tauY")


@dataclass(frozen=True)
class OpenCV(LensDistortion):
    """OpenCV's distortion coefficients (``distCoeffs`` order: k1, k2, p1, p2, k3, k4, k5, k6)."""

    k1: float = 0.0
    k2: float = 0.0
    p1: float = 0.0
    p2: float = 0.0
    k3: float = 0.0
    k4: float = 0.0
    k5: float = 0.0
    k6: float = 0.0

    name: ClassVar[str] = "opencv"
    summary: ClassVar[str] = ("pinhole with OpenCV's radial-tangential lens distortion (from a "
                              "camera file; --fov as perspective, keeping the distortion)")
    colmap_names: ClassVar[tuple[str, ...]] = tuple(COLMAP_MODELS)
    transforms_names: ClassVar[tuple[str, ...]] = ("OPENCV",)
    transforms_fields: ClassVar[tuple[str, ...]] = ("k1", "k2", "k3", "k4", "p1", "p2")

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            try:
                value = float(value)
            except (TypeError, ValueError):
                value = math.nan
            if not math.isfinite(value):
                raise CameraError(f"camera distortion {f.name} must be a finite number, got "
                                  f"{getattr(self, f.name)!r}")
            object.__setattr__(self, f.name, value)

    @property
    def coefficients(self) -> tuple[float, ...]:
        """The eight coefficients in OpenCV's ``distCoeffs`` order."""
        return tuple(getattr(self, f.name) for f in fields(self))

    # ------------------------------------------------------------------ float64/float32 twins
    def project(self, p_cam, camera):
        dt = p_cam.dtype.type
        fx, fy, cx, cy = (dt(v) for v in (camera.fx, camera.fy, camera.cx, camera.cy))
        nd = distort(p_cam[:, :2] / p_cam[:, 2:3], self)
        return np.stack([fx * nd[:, 0] + cx, fy * nd[:, 1] + cy], -1)

    def jacobian(self, p_cam, camera):
        dt = p_cam.dtype.type
        z = p_cam[:, 2]
        a_lo, a_hi, b_lo, b_hi = (dt(v) for v in self.jacobian_box(camera))
        n = np.stack([np.clip(p_cam[:, 0] / z, a_lo, a_hi), np.clip(p_cam[:, 1] / z, b_lo, b_hi)], -1)
        d00, d01, d11 = distort_jacobian(n, self)
        fx, fy = dt(camera.fx), dt(camera.fy)
        j = np.empty((p_cam.shape[0], 2, 3), p_cam.dtype)
        # rows of D P: P row 0 = (1/z, 0, -a/z), P row 1 = (0, 1/z, -b/z), (a, b) clamped
        for row, f, (da, db) in ((0, fx, (d00, d01)), (1, fy, (d01, d11))):
            j[:, row, 0] = f * da / z
            j[:, row, 1] = f * db / z
            j[:, row, 2] = -f * (da * n[:, 0] + db * n[:, 1]) / z
        return j

    def visible(self, p_cam, camera, near):
        dt = p_cam.dtype.type
        keep = p_cam[:, 2] > near
        zs = np.where(keep, p_cam[:, 2], dt(1))
        r2 = (p_cam[:, 0] / zs) ** 2 + (p_cam[:, 1] / zs) ** 2
        return keep & (r2 < dt(self.r2_limit()))

    def r2_limit(self) -> float:
        """Squared normalised radius beyond which centres are not drawn (the fold; the largest
        float32 where there is none)."""
        r = fold_radius(self)
        return float(np.finfo(np.float32).max) if math.isinf(r) else r * r

    def bounds(self, camera: "Camera", margin: float = 0.0) -> tuple[float, float, float, float]:
        """:func:`tangent_bounds` of ``camera``'s image widened by ``margin`` px."""
        return tangent_bounds(self, camera.fx, camera.fy, camera.cx, camera.cy, camera.width,
                              camera.height, margin)

    def jacobian_box(self, camera: "Camera") -> tuple[float, float, float, float]:
        """``(a_lo, a_hi, b_lo, b_hi)``: where ``x/z``, ``y/z`` are clamped inside the Jacobian,
        the image's tangent bounds widened by ``(JACOBIAN_CLAMP - 1) / 2`` of their width on
        each side (a centred pinhole's ``+-JACOBIAN_CLAMP tan(half fov)``)."""
        a_lo, a_hi, b_lo, b_hi = self.bounds(camera)
        wa, wb = 0.5 * (JACOBIAN_CLAMP - 1.0) * (a_hi - a_lo), 0.5 * (JACOBIAN_CLAMP - 1.0) * (b_hi - b_lo)
        return a_lo - wa, a_hi + wa, b_lo - wb, b_hi + wb

    def cull_frustum(self, camera):
        """A pinhole camera (``camera``'s pose and focal lengths) whose image spans the tangent
        bounds of ``camera``'s image widened by :data:`CULL_MARGIN_PX`."""
        from .camera import Camera

        a_lo, a_hi, b_lo, b_hi = self.bounds(camera, CULL_MARGIN_PX)
        width = max(1, math.ceil((a_hi - a_lo) * camera.fx))
        height = max(1, math.ceil((b_hi - b_lo) * camera.fy))
        return Camera(width, height, camera.fx, camera.fy, -a_lo * camera.fx, -b_lo * camera.fy,
                      camera.world_to_camera, Pinhole())

    # ------------------------------------------------------------------ the GPU side
    def uniforms(self, camera):
        return {"u_cv_num": (self.k1, self.k2, self.k3), "u_cv_den": (self.k4, self.k5, self.k6),
                "u_cv_tangential": (self.p1, self.p2), "u_cv_r2_limit": self.r2_limit(),
                "u_cv_jac_box": self.jacobian_box(camera)}

    @classmethod
    def intrinsics(cls, width, height, fov_degrees, like=None):
        """The pinhole's (vertical field of view, default 50) with ``like``'s distortion when
        it has one; without a field of view an OpenCV or pinhole ``like`` keeps its intrinsics."""
        model = like.model if like is not None and isinstance(like.model, OpenCV) else cls()
        if fov_degrees is None and like is not None and isinstance(like.model, (OpenCV, Pinhole)):
            return like.fx, like.fy, like.cx, like.cy, model
        fx, fy, cx, cy, _ = Pinhole.intrinsics(width, height, DEFAULT_FOV if fov_degrees is None
                                               else fov_degrees)
        return fx, fy, cx, cy, model

    @classmethod
    def fov_range(cls):
        return Pinhole.fov_range()

    # ------------------------------------------------------------------ files
    def to_json(self):
        c = self.coefficients
        size = 8 if any(c[5:]) else (5 if c[4] else 4)
        return {"distortion": list(c[:size])}

    @classmethod
    def from_json(cls, obj, path, where=""):
        """``"distortion"``: OpenCV's ``distCoeffs``, 4, 5 or 8 numbers (k1 k2 p1 p2 [k3 [k4 k5
        k6]]), or OpenCV's 12 or 14 when the thin-prism and tilt terms after them (s1 s2 s3 s4
        [tauX tauY]) are 0, as ``cv2.calibrateCamera`` writes without those flags; absent: none."""
        from .json_fields import matrix

        coeffs = obj.get("distortion", [0.0] * 4)
        field = f"{path}: {where}field 'distortion'"
        if not isinstance(coeffs, list) or len(coeffs) not in DISTORTION_COUNTS:
            got = len(coeffs) if isinstance(coeffs, list) else repr(coeffs)
            raise CameraError(f"{field} must be a list of 4, 5 or 8 numbers (OpenCV's k1 k2 p1 p2 "
                              f"[k3 [k4 k5 k6]]; 12 or 14 with s1..s4, tauX, tauY 0), got {got}")
        values = matrix(path, where, {"distortion": coeffs}, "distortion", (len(coeffs),))
        extra = [name for name, v in zip(EXTRA_TERMS, values[8:]) if v != 0]
        if extra:
            raise CameraError(f"{field}: OpenCV's thin-prism and tilted-sensor terms ("
                              f"{', '.join(extra)} here) are not supported; the opencv camera "
                              f"takes k1 k2 p1 p2 [k3 [k4 k5 k6]] (the rest of its "
                              f"{len(coeffs)} numbers must be 0)")
        return cls(*values[:8])

    @classmethod
    def from_colmap(cls, name, params):
        """COLMAP's models by their parameters; zero distortion is a pinhole."""
        focals, keys = COLMAP_MODELS[name]
        values = dict(zip(keys, params[2 + focals:]))
        model = cls(**values) if any(values.values()) else Pinhole()
        return (*colmap_intrinsics(params, focals), model)

    def to_colmap(self, camera):
        """The smallest COLMAP model that holds the camera exactly."""
        c = self.coefficients
        if camera.fx == camera.fy and not any(c[2:]):
            name = "RADIAL" if self.k2 else "SIMPLE_RADIAL"
            return name, (camera.fx, camera.cx, camera.cy, *c[:1 + bool(self.k2)])
        name, size = ("FULL_OPENCV", 8) if any(c[4:]) else ("OPENCV", 4)
        return name, (camera.fx, camera.fy, camera.cx, camera.cy, *c[:size])

    @classmethod
    def from_transforms(cls, name, fields):
        """nerfstudio's OPENCV: k1, k2, k3 (radial numerator), p1, p2; its ``k4`` is an
        ``r^8`` numerator term (not OpenCV's k4), which this model has not: refused unless 0."""
        v = {k: fields.get(k) or 0.0 for k in cls.transforms_fields}
        if v["k4"]:
            raise CameraError(f"field 'k4' = {v['k4']:g}: nerfstudio's r^8 radial term, which "
                              "splatgl's opencv camera does not have; undistort the images first")
        del v["k4"]
        return cls(**v) if any(v.values()) else Pinhole()

    def to_transforms(self):
        if self.k4 or self.k5 or self.k6:
            raise CameraError("transforms.json has no fields for OpenCV's rational terms k4..k6 "
                              "(nerfstudio's k4 is an r^8 term)")
        return {"camera_model": "OPENCV", "k1": self.k1, "k2": self.k2, "k3": self.k3,
                "p1": self.p1, "p2": self.p2}
