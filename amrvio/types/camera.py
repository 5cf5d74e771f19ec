"""Monocular camera models: pinhole, + radial-tangential, + equidistant (Kannala-Brandt), + FOV.

Conventions
-----------
- Pixel coordinates: ``(N, 2)`` arrays ``[u, v]``, ``u`` along the image columns, ``v`` along the rows,
  the centre of the top-left pixel at ``(0, 0)`` (OpenCV, Kalibr and EuRoC convention).
- Camera frame: x right, y down, z forward. ``points_cam`` are ``(N, 3)`` points in that frame.
- Normalised coordinates ``x_n = (X/Z, Y/Z)``; every model maps them to distorted normalised coordinates
  ``x_d = d(x_n)`` and then to pixels ``u = fx * x_d + cx``, ``v = fy * y_d + cy`` (no skew).
- Points with ``Z <= 0`` cannot be projected: :meth:`CameraModel.project` returns a NaN row for them.

Models
------
- :class:`PinholeCamera`: ``d(x_n) = x_n`` (Kalibr ``none``).
- :class:`RadTanCamera`: OpenCV ``plumb_bob`` / Kalibr ``radtan`` (Brown-Conrady):
  ``x_d = x (1 + k1 r^2 + k2 r^4 + k3 r^6) + 2 p1 x y + p2 (r^2 + 2 x^2)``,
  ``y_d = y (1 + k1 r^2 + k2 r^4 + k3 r^6) + p1 (r^2 + 2 y^2) + 2 p2 x y``.
- :class:`FovCamera`: Devernay-Faugeras 2001 FOV model (DSO, TUM monoVO, Kalibr ``fov``):
  ``r_d = atan(2 r tan(omega/2)) / omega``, ``x_d = (r_d / r) x_n``.
- :class:`EquidistantCamera`: Kannala-Brandt 2006 as in ``cv2.fisheye`` / Kalibr ``equidistant``:
  ``theta = atan(r)``, ``theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)``,
  ``x_d = (theta_d / r) x_n``.
"""

from __future__ import annotations

import functools
import math
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from amrvio.errors import ShapeError

FloatArray = NDArray[np.float64]

# Newton iterations for the inverse distortion; quadratic convergence reaches machine precision in
# a handful of steps, the cap only bounds points outside the invertible region.
_MAX_NEWTON_ITERS = 50
# A row whose inverse leaves a residual above this (pixels) is declared not invertible (NaN).
_UNPROJECT_FAIL_PX = 1e-6


def _as_points(arr: ArrayLike, cols: int, what: str) -> FloatArray:
    """Return ``arr`` as a finite ``(N, cols)`` float64 array or raise ShapeError."""
    a = np.asarray(arr, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != cols:
        raise ShapeError(f"{what} must have shape (N, {cols}), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ShapeError(f"{what} contains NaN or infinite values")
    return a


def _param(name: str, raw: object, positive: bool = False) -> float:
    """``raw`` as a finite float (positive if asked) or ShapeError."""
    try:
        value = float(raw)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ShapeError(f"camera parameter {name} must be a number, got {raw!r}") from None
    if not math.isfinite(value):
        raise ShapeError(f"camera parameter {name} must be finite, got {value}")
    if positive and value <= 0.0:
        raise ShapeError(f"camera parameter {name} must be positive, got {value}")
    return value


@dataclass(frozen=True, slots=True)
class CameraModel(ABC):
    """Shared interface and the parts common to every pinhole-based model.

    Subclasses supply the distortion map in normalised coordinates, its Jacobian and its inverse.
    ``width``/``height`` are in pixels; ``fx, fy`` focal lengths and ``cx, cy`` principal point in pixels.
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    distortion_model: ClassVar[str] = "none"

    def __post_init__(self) -> None:
        for name in ("width", "height"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer):
                raise ShapeError(f"camera {name} must be an integer, got {value!r}")
            if value <= 0:
                raise ShapeError(f"camera {name} must be positive, got {value}")
            object.__setattr__(self, name, int(value))
        for name in ("fx", "fy", "cx", "cy"):
            positive = name in ("fx", "fy")
            object.__setattr__(self, name, _param(name, getattr(self, name), positive))
        for name in self._distortion_fields():
            object.__setattr__(self, name, _param(name, getattr(self, name)))
        self._validate_model()

    def _validate_model(self) -> None:
        """Model-specific parameter checks (raise ShapeError); none by default."""
        return None

    # ----- model specific ---------------------------------------------------------------------------

    @classmethod
    def _distortion_fields(cls) -> tuple[str, ...]:
        return ()

    @abstractmethod
    def _distort(self, xn: FloatArray) -> FloatArray:
        """(N, 2) normalised -> (N, 2) distorted normalised coordinates."""

    @abstractmethod
    def _distort_jacobian(self, xn: FloatArray) -> FloatArray:
        """(N, 2, 2) d(distorted normalised)/d(normalised)."""

    @abstractmethod
    def _undistort_normalized(self, xd: FloatArray) -> FloatArray:
        """(N, 2) distorted normalised -> (N, 2) normalised; NaN rows where not invertible."""

    # ----- shared API -------------------------------------------------------------------------------

    @property
    def K(self) -> FloatArray:
        """(3, 3) intrinsic matrix."""
        return np.array(
            [[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]], dtype=np.float64
        )

    @property
    def distortion(self) -> tuple[float, ...]:
        """Distortion coefficients in the order of the model (OpenCV order for radtan)."""
        return tuple(float(getattr(self, name)) for name in self._distortion_fields())

    @property
    def resolution(self) -> tuple[int, int]:
        """``(width, height)`` in pixels."""
        return (self.width, self.height)

    def project(self, points_cam: ArrayLike) -> FloatArray:
        """Project ``(N, 3)`` camera-frame points to ``(N, 2)`` pixels.

        Rows with ``Z <= 0`` are NaN. Points outside the image are projected all the same.
        """
        p = _as_points(points_cam, 3, "points_cam")
        out = np.full((p.shape[0], 2), np.nan)
        front = p[:, 2] > 0.0
        if np.any(front):
            pf = p[front]
            xn = pf[:, :2] / pf[:, 2:3]
            out[front] = self._to_pixels(self._distort(xn))
        return out

    def project_jacobian(self, points_cam: ArrayLike) -> FloatArray:
        """``(N, 2, 3)`` analytic d(pixel)/d(point) at ``(N, 3)`` camera-frame points; NaN for Z <= 0."""
        p = _as_points(points_cam, 3, "points_cam")
        out = np.full((p.shape[0], 2, 3), np.nan)
        front = p[:, 2] > 0.0
        if np.any(front):
            pf = p[front]
            inv_z = 1.0 / pf[:, 2]
            xn = pf[:, :2] * inv_z[:, None]
            # d x_n / d P = [[1/z, 0, -x/z^2], [0, 1/z, -y/z^2]]
            dxn_dp = np.zeros((pf.shape[0], 2, 3))
            dxn_dp[:, 0, 0] = inv_z
            dxn_dp[:, 1, 1] = inv_z
            dxn_dp[:, 0, 2] = -xn[:, 0] * inv_z
            dxn_dp[:, 1, 2] = -xn[:, 1] * inv_z
            jd = self._distort_jacobian(xn)
            jd[:, 0, :] *= self.fx
            jd[:, 1, :] *= self.fy
            out[front] = jd @ dxn_dp
        return out

    def unproject(self, uv: ArrayLike) -> FloatArray:
        """``(N, 2)`` pixels -> ``(N, 3)`` rays ``[x_n, y_n, 1]`` (not unit length).

        The distortion is inverted by Newton iterations to machine precision. Rows outside the region
        where the distortion is invertible (beyond its fold, or beyond 90 degrees for the equidistant
        model) are NaN.
        """
        px = _as_points(uv, 2, "uv")
        xd = np.empty_like(px)
        xd[:, 0] = (px[:, 0] - self.cx) / self.fx
        xd[:, 1] = (px[:, 1] - self.cy) / self.fy
        xn = self._undistort_normalized(xd)
        rays = np.concatenate([xn, np.ones((xn.shape[0], 1))], axis=1)
        rays[np.isnan(xn[:, 0])] = np.nan
        return rays

    def undistort_points(self, uv: ArrayLike) -> FloatArray:
        """``(N, 2)`` distorted pixels -> ``(N, 2)`` pixels of :meth:`pinhole` (same K); NaN rows as
        in :meth:`unproject`."""
        rays = self.unproject(uv)
        return self._to_pixels(rays[:, :2])

    def distort_points(self, uv_pinhole: ArrayLike) -> FloatArray:
        """Inverse of :meth:`undistort_points`: ``(N, 2)`` ideal pinhole pixels -> distorted pixels."""
        px = _as_points(uv_pinhole, 2, "uv_pinhole")
        xn = np.empty_like(px)
        xn[:, 0] = (px[:, 0] - self.cx) / self.fx
        xn[:, 1] = (px[:, 1] - self.cy) / self.fy
        return self._to_pixels(self._distort(xn))

    def in_image(self, uv: ArrayLike, border_px: float = 0.0) -> NDArray[np.bool_]:
        """``(N,)`` True where ``(N, 2)`` pixels lie at least ``border_px`` inside the image."""
        px = np.asarray(uv, dtype=np.float64)
        if px.ndim != 2 or px.shape[1] != 2:
            raise ShapeError(f"uv must have shape (N, 2), got {px.shape}")
        with np.errstate(invalid="ignore"):
            return (
                (px[:, 0] >= -0.5 + border_px)
                & (px[:, 0] <= self.width - 0.5 - border_px)
                & (px[:, 1] >= -0.5 + border_px)
                & (px[:, 1] <= self.height - 0.5 - border_px)
            )

    def undistort_image(self, img: NDArray[np.generic]) -> NDArray[np.generic]:
        """Resample ``(H, W)`` or ``(H, W, C)`` image into :meth:`pinhole` (same size, same K).

        Bilinear interpolation; pixels that map outside the source image are 0. The remap tables are
        cached per camera.
        """
        import cv2

        a = np.asarray(img)
        if a.ndim not in (2, 3) or a.shape[:2] != (self.height, self.width):
            raise ShapeError(
                f"image must have shape ({self.height}, {self.width}[, C]) for this camera, "
                f"got {a.shape}"
            )
        map_x, map_y = _undistort_maps(self)
        out: NDArray[np.generic] = cv2.remap(
            a, map_x, map_y, interpolation=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT
        )
        if out.ndim == 2 and a.ndim == 3:  # cv2 drops a single channel axis
            out = out[:, :, None]
        return out

    def pinhole(self) -> PinholeCamera:
        """The ideal pinhole camera with the same size and K."""
        return PinholeCamera(self.width, self.height, self.fx, self.fy, self.cx, self.cy)

    def scaled(self, factor: float) -> CameraModel:
        """The same camera on an image resized by ``factor`` (0.5 for one pyramid level down).

        Pixel centres stay consistent: ``u' = factor (u + 0.5) - 0.5``, so ``fx' = factor fx`` and
        ``cx' = factor (cx + 0.5) - 0.5``. The size is ``round(factor * width)``; distortion
        coefficients act on normalised coordinates and do not change.
        """
        f = float(factor)
        if not math.isfinite(f) or f <= 0.0:
            raise ShapeError(f"scale factor must be positive and finite, got {factor}")
        width = max(1, int(round(self.width * f)))
        height = max(1, int(round(self.height * f)))
        return self._with_intrinsics(
            width,
            height,
            self.fx * f,
            self.fy * f,
            (self.cx + 0.5) * f - 0.5,
            (self.cy + 0.5) * f - 0.5,
        )

    @abstractmethod
    def _with_intrinsics(
        self, width: int, height: int, fx: float, fy: float, cx: float, cy: float
    ) -> CameraModel:
        """A copy with other size and intrinsics and the same distortion."""

    def _to_pixels(self, xd: FloatArray) -> FloatArray:
        out = np.empty_like(xd)
        out[:, 0] = self.fx * xd[:, 0] + self.cx
        out[:, 1] = self.fy * xd[:, 1] + self.cy
        return out

    def _pixel_residual_ok(self, xn: FloatArray, xd: FloatArray) -> NDArray[np.bool_]:
        """True where the distortion of ``xn`` reproduces ``xd`` to _UNPROJECT_FAIL_PX pixels."""
        err = self._distort(xn) - xd
        err_px = np.hypot(err[:, 0] * self.fx, err[:, 1] * self.fy)
        ok: NDArray[np.bool_] = np.isfinite(err_px) & (err_px < _UNPROJECT_FAIL_PX)
        return ok


@functools.lru_cache(maxsize=4)
def _undistort_maps(camera: CameraModel) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Remap tables: for each pixel of the ideal pinhole image, where to sample the distorted one."""
    us, vs = np.meshgrid(
        np.arange(camera.width, dtype=np.float64), np.arange(camera.height, dtype=np.float64)
    )
    uv = np.stack([us.ravel(), vs.ravel()], axis=1)
    src = camera.distort_points(uv)
    src[~np.isfinite(src)] = -1e6  # sample outside: black
    map_x = src[:, 0].reshape(camera.height, camera.width).astype(np.float32)
    map_y = src[:, 1].reshape(camera.height, camera.width).astype(np.float32)
    map_x.setflags(write=False)
    map_y.setflags(write=False)
    return map_x, map_y


@dataclass(frozen=True, slots=True)
class PinholeCamera(CameraModel):
    """Ideal pinhole camera without distortion (Kalibr ``pinhole`` + ``none``)."""

    distortion_model: ClassVar[str] = "none"

    def _distort(self, xn: FloatArray) -> FloatArray:
        return xn.copy()

    def _distort_jacobian(self, xn: FloatArray) -> FloatArray:
        return np.broadcast_to(np.eye(2), (xn.shape[0], 2, 2)).copy()

    def _undistort_normalized(self, xd: FloatArray) -> FloatArray:
        return xd.copy()

    def _with_intrinsics(
        self, width: int, height: int, fx: float, fy: float, cx: float, cy: float
    ) -> PinholeCamera:
        return PinholeCamera(width, height, fx, fy, cx, cy)


@dataclass(frozen=True, slots=True)
class RadTanCamera(CameraModel):
    """Pinhole + radial-tangential distortion (OpenCV ``plumb_bob``, Kalibr ``radtan``).

    ``distortion`` is ``(k1, k2, p1, p2, k3)``, the order ``cv2.projectPoints`` takes.
    """

    k1: float
    k2: float
    p1: float
    p2: float
    k3: float = 0.0

    distortion_model: ClassVar[str] = "radtan"

    @classmethod
    def _distortion_fields(cls) -> tuple[str, ...]:
        return ("k1", "k2", "p1", "p2", "k3")

    def _distort(self, xn: FloatArray) -> FloatArray:
        x = xn[:, 0]
        y = xn[:, 1]
        r2 = x * x + y * y
        radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3))
        out = np.empty_like(xn)
        out[:, 0] = x * radial + 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x)
        out[:, 1] = y * radial + self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y
        return out

    def _distort_jacobian(self, xn: FloatArray) -> FloatArray:
        x = xn[:, 0]
        y = xn[:, 1]
        r2 = x * x + y * y
        radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3))
        dradial_dr2 = self.k1 + r2 * (2.0 * self.k2 + 3.0 * self.k3 * r2)
        j = np.empty((xn.shape[0], 2, 2))
        j[:, 0, 0] = radial + 2.0 * x * x * dradial_dr2 + 2.0 * self.p1 * y + 6.0 * self.p2 * x
        j[:, 0, 1] = 2.0 * x * y * dradial_dr2 + 2.0 * self.p1 * x + 2.0 * self.p2 * y
        j[:, 1, 0] = 2.0 * x * y * dradial_dr2 + 2.0 * self.p1 * x + 2.0 * self.p2 * y
        j[:, 1, 1] = radial + 2.0 * y * y * dradial_dr2 + 6.0 * self.p1 * y + 2.0 * self.p2 * x
        return j

    def _undistort_normalized(self, xd: FloatArray) -> FloatArray:
        xn = xd.copy()
        for _ in range(_MAX_NEWTON_ITERS):
            res = self._distort(xn) - xd
            if np.all(np.abs(res) <= 1e-15 * (1.0 + np.abs(xd))):
                break
            j = self._distort_jacobian(xn)
            det = j[:, 0, 0] * j[:, 1, 1] - j[:, 0, 1] * j[:, 1, 0]
            with np.errstate(divide="ignore", invalid="ignore"):
                dx = (j[:, 1, 1] * res[:, 0] - j[:, 0, 1] * res[:, 1]) / det
                dy = (-j[:, 1, 0] * res[:, 0] + j[:, 0, 0] * res[:, 1]) / det
            step = np.stack([dx, dy], axis=1)
            step[~np.isfinite(step)] = 0.0
            xn = xn - step
            if not np.all(np.isfinite(xn)):
                xn[~np.isfinite(xn)] = np.nan
                break
        # A valid inverse reproduces xd and lies where the map is orientation preserving (before the
        # fold of the radial polynomial).
        j = self._distort_jacobian(xn)
        det = j[:, 0, 0] * j[:, 1, 1] - j[:, 0, 1] * j[:, 1, 0]
        ok = self._pixel_residual_ok(xn, xd) & (det > 0.0)
        xn[~ok] = np.nan
        return xn

    def _with_intrinsics(
        self, width: int, height: int, fx: float, fy: float, cx: float, cy: float
    ) -> RadTanCamera:
        return RadTanCamera(
            width, height, fx, fy, cx, cy, self.k1, self.k2, self.p1, self.p2, self.k3
        )


@dataclass(frozen=True, slots=True)
class EquidistantCamera(CameraModel):
    """Pinhole + equidistant fisheye distortion (Kannala-Brandt; ``cv2.fisheye``; Kalibr
    ``equidistant``). ``distortion`` is ``(k1, k2, k3, k4)``. Only rays with Z > 0 are modelled."""

    k1: float
    k2: float
    k3: float
    k4: float

    distortion_model: ClassVar[str] = "equidistant"

    @classmethod
    def _distortion_fields(cls) -> tuple[str, ...]:
        return ("k1", "k2", "k3", "k4")

    def _theta_d(self, theta: FloatArray) -> FloatArray:
        t2 = theta * theta
        # Kannala-Brandt 2006 eq. 6 with 4 coefficients
        poly = 1.0 + t2 * (self.k1 + t2 * (self.k2 + t2 * (self.k3 + t2 * self.k4)))
        out: FloatArray = theta * poly
        return out

    def _dtheta_d(self, theta: FloatArray) -> FloatArray:
        t2 = theta * theta
        out: FloatArray = 1.0 + t2 * (
            3.0 * self.k1 + t2 * (5.0 * self.k2 + t2 * (7.0 * self.k3 + t2 * 9.0 * self.k4))
        )
        return out

    def _distort(self, xn: FloatArray) -> FloatArray:
        r = np.hypot(xn[:, 0], xn[:, 1])
        theta = np.arctan(r)
        safe_r = np.where(r > 0.0, r, 1.0)
        scale = np.where(r > 0.0, self._theta_d(theta) / safe_r, 1.0)
        out: FloatArray = xn * scale[:, None]
        return out

    def _distort_jacobian(self, xn: FloatArray) -> FloatArray:
        # x_d = s(r) x_n  =>  J = s I + (s'(r) / r) x_n x_n^T
        r = np.hypot(xn[:, 0], xn[:, 1])
        theta = np.arctan(r)
        small = r < 1e-6
        safe_r = np.where(small, 1.0, r)
        s = np.where(small, 1.0, self._theta_d(theta) / safe_r)
        ds_dr = (self._dtheta_d(theta) / (1.0 + r * r) * r - self._theta_d(theta)) / (safe_r**2)
        # s(r) = 1 + (k1 - 1/3) r^2 + O(r^4) near 0, so s'(r)/r -> 2 (k1 - 1/3)
        g = np.where(small, 2.0 * (self.k1 - 1.0 / 3.0), ds_dr / safe_r)
        j = g[:, None, None] * (xn[:, :, None] * xn[:, None, :])
        j[:, 0, 0] += s
        j[:, 1, 1] += s
        return j

    def _undistort_normalized(self, xd: FloatArray) -> FloatArray:
        theta_d = np.hypot(xd[:, 0], xd[:, 1])
        theta = theta_d.copy()
        for _ in range(_MAX_NEWTON_ITERS):
            res = self._theta_d(theta) - theta_d
            if np.all(np.abs(res) <= 1e-15 * (1.0 + theta_d)):
                break
            with np.errstate(divide="ignore", invalid="ignore"):
                step = res / self._dtheta_d(theta)
            step[~np.isfinite(step)] = 0.0
            # stay inside [0, pi/2): the model only covers rays in front of the camera
            theta = np.clip(theta - step, 0.0, 0.5 * np.pi - 1e-9)
        valid = (self._dtheta_d(theta) > 0.0) & (theta < 0.5 * np.pi - 1e-8)
        r = np.tan(theta)
        safe_td = np.where(theta_d > 0.0, theta_d, 1.0)
        scale = np.where(theta_d > 0.0, r / safe_td, 1.0)
        xn = xd * scale[:, None]
        ok = valid & self._pixel_residual_ok(xn, xd)
        xn[~ok] = np.nan
        return xn

    def _with_intrinsics(
        self, width: int, height: int, fx: float, fy: float, cx: float, cy: float
    ) -> EquidistantCamera:
        return EquidistantCamera(
            width, height, fx, fy, cx, cy, self.k1, self.k2, self.k3, self.k4
        )


@dataclass(frozen=True, slots=True)
class FovCamera(CameraModel):
    """Pinhole + FOV (arctan) distortion of Devernay & Faugeras 2001, as in DSO / TUM monoVO and
    Kalibr ``fov``: ``r_d = atan(2 r tan(omega / 2)) / omega``, ``x_d = (r_d / r) x_n``.
    ``distortion`` is ``(omega,)`` in radians; ``omega = 0`` is the pinhole."""

    omega: float

    distortion_model: ClassVar[str] = "fov"

    @classmethod
    def _distortion_fields(cls) -> tuple[str, ...]:
        return ("omega",)

    def _validate_model(self) -> None:
        if not 0.0 <= self.omega < np.pi:
            raise ShapeError(f"FOV omega must be in [0, pi), got {self.omega}")

    def _scale_and_slope(self, r: FloatArray) -> tuple[FloatArray, FloatArray]:
        """s(r) = r_d / r and g(r) = s'(r) / r (Devernay & Faugeras 2001, eq. 13)."""
        w = self.omega
        if w == 0.0:
            return np.ones_like(r), np.zeros_like(r)
        a = 2.0 * math.tan(0.5 * w)
        small = r < 1e-6
        safe_r = np.where(small, 1.0, r)
        ar = a * safe_r
        s = np.where(small, a / w, np.arctan(ar) / (w * safe_r))
        ds_dr = (ar / (1.0 + ar * ar) - np.arctan(ar)) / (w * safe_r**2)
        # s(r) = a/w - a^3 r^2 / (3 w) + O(r^4)  =>  s'(r)/r -> -2 a^3 / (3 w)
        g = np.where(small, -2.0 * a**3 / (3.0 * w), ds_dr / safe_r)
        return s, g

    def _distort(self, xn: FloatArray) -> FloatArray:
        s, _ = self._scale_and_slope(np.hypot(xn[:, 0], xn[:, 1]))
        out: FloatArray = xn * s[:, None]
        return out

    def _distort_jacobian(self, xn: FloatArray) -> FloatArray:
        s, g = self._scale_and_slope(np.hypot(xn[:, 0], xn[:, 1]))
        j = g[:, None, None] * (xn[:, :, None] * xn[:, None, :])
        j[:, 0, 0] += s
        j[:, 1, 1] += s
        return j

    def _undistort_normalized(self, xd: FloatArray) -> FloatArray:
        w = self.omega
        if w == 0.0:
            return xd.copy()
        # closed-form inverse: r = tan(r_d w) / (2 tan(w / 2)), defined for r_d w < pi / 2
        a = 2.0 * math.tan(0.5 * w)
        rd = np.hypot(xd[:, 0], xd[:, 1])
        valid = rd * w < 0.5 * np.pi
        small = rd < 1e-9
        with np.errstate(invalid="ignore"):
            r = np.where(valid, np.tan(np.minimum(rd * w, 0.5 * np.pi - 1e-12)) / a, np.nan)
            scale = np.where(small, w / a, r / np.where(small, 1.0, rd))
        xn: FloatArray = xd * scale[:, None]
        return xn

    def _with_intrinsics(
        self, width: int, height: int, fx: float, fy: float, cx: float, cy: float
    ) -> FovCamera:
        return FovCamera(width, height, fx, fy, cx, cy, self.omega)


_RADTAN_NAMES = frozenset({"radtan", "radial-tangential", "radial_tangential", "plumb_bob"})
_EQUIDISTANT_NAMES = frozenset({"equidistant", "equi", "fisheye", "kannala-brandt", "kannala_brandt"})
_NONE_NAMES = frozenset({"none", ""})
_FOV_NAMES = frozenset({"fov", "atan"})


def canonical_distortion_model(distortion_model: str) -> str:
    """``none``, ``radtan`` or ``equidistant`` for a name or alias; ValueError if unknown."""
    name = distortion_model.strip().lower()
    if name in _NONE_NAMES:
        return "none"
    if name in _RADTAN_NAMES:
        return "radtan"
    if name in _EQUIDISTANT_NAMES:
        return "equidistant"
    if name in _FOV_NAMES:
        return "fov"
    raise ValueError(
        f"distortion model {distortion_model!r} is not supported "
        "(use none, radtan, equidistant or fov)"
    )


# Number of distortion coefficients each model takes (``none``: any number of zeros).
DISTORTION_COUNTS: dict[str, tuple[int, ...] | None] = {
    "none": None,
    "radtan": (4, 5),
    "equidistant": (4,),
    "fov": (1,),
}


def camera_from_params(
    model: str,
    distortion_model: str,
    intrinsics: Sequence[float],
    distortion: Sequence[float],
    resolution: Sequence[float],
) -> CameraModel:
    """Build a camera from Kalibr-style parameters.

    ``model`` is the projection (only ``pinhole``), ``distortion_model`` one of ``none``,
    ``radtan`` (aliases ``radial-tangential``, ``plumb_bob``: 4 or 5 coefficients k1 k2 p1 p2 [k3])
    ``equidistant`` (aliases ``fisheye``, ``kannala-brandt``: 4 coefficients k1..k4) or ``fov``
    (1 coefficient omega).
    ``intrinsics`` is ``[fx, fy, cx, cy]`` and ``resolution`` ``[width, height]``.

    Raises ValueError for an unknown model (ShapeError, a ValueError, for wrong counts or values).
    """
    model_name = model.strip().lower()
    if model_name != "pinhole":
        raise ValueError(f"camera model {model!r} is not supported (only 'pinhole')")
    intr = [float(v) for v in intrinsics]
    if len(intr) != 4:
        raise ShapeError(f"intrinsics must be [fx, fy, cx, cy], got {len(intr)} values")
    res = list(resolution)
    if len(res) != 2:
        raise ShapeError(f"resolution must be [width, height], got {len(res)} values")
    width_f, height_f = float(res[0]), float(res[1])
    if not (width_f.is_integer() and height_f.is_integer()):
        raise ShapeError(f"resolution must be integers, got {res}")
    width, height = int(width_f), int(height_f)
    dist = [float(v) for v in distortion]
    fx, fy, cx, cy = intr
    dist_name = canonical_distortion_model(distortion_model)
    if dist_name == "none":
        if any(v != 0.0 for v in dist):
            raise ShapeError("distortion model 'none' takes no non-zero coefficients")
        return PinholeCamera(width, height, fx, fy, cx, cy)
    if dist_name == "radtan":
        if len(dist) not in (4, 5):
            raise ShapeError(
                f"radtan distortion takes 4 or 5 coefficients (k1 k2 p1 p2 [k3]), got {len(dist)}"
            )
        return RadTanCamera(width, height, fx, fy, cx, cy, *dist)
    if dist_name == "fov":
        if len(dist) != 1:
            raise ShapeError(f"fov distortion takes 1 coefficient (omega), got {len(dist)}")
        return FovCamera(width, height, fx, fy, cx, cy, dist[0])
    if len(dist) != 4:
        raise ShapeError(f"equidistant distortion takes 4 coefficients, got {len(dist)}")
    return EquidistantCamera(width, height, fx, fy, cx, cy, *dist)
