"""Image formation: exposure, vignetting, response curve, noise, quantisation and motion blur.

Photometric model (seed §4 and §6.2; Engel et al. 2016 "A photometrically calibrated benchmark"):

    I(x) = G( gain * t * V(x) * B(x) + noise ),

with ``B`` the scene radiance (SceneRenderer.irradiance), ``t`` the exposure time in seconds, ``V``
the radial vignetting (amrvio.photometric.model.RadialVignette: 1 + v1 r^2 + v2 r^4 + v3 r^6), ``G``
the camera response ([0, 1] -> [0, 1], monotone) and 8-bit quantisation with saturation. Energy
units: ``t * V * B == 1`` fills the pixel's full well (and the 8-bit range at unit gain). Noise:
photon shot noise on the collected electrons (Gaussian approximation of Poisson, variance =
electrons; the well saturates at ``full_well_e``), amplified by the analog gain, plus read noise (in
DN of the linear signal), drawn as one Gaussian per pixel; then clipping, the response curve and
rounding to 8 bits.

Motion blur (seed §5, temporal integral): the image of an exposure window is the average of sub-frame
radiance renders over ``[t_start, t_start + T]`` (midpoint rule), exposed once. The number of
sub-frames follows the predicted pixel smear so that consecutive sub-frames move less than
``max_subframe_px``; the smear is the true image motion of the visible scene points (rotation and
translation, using the depth map).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ShapeError
from amrvio.photometric.model import RadialVignette
from amrvio.sim.blackout import open_pieces
from amrvio.sim.render import SceneRenderer
from amrvio.types.camera import CameraModel
from amrvio.types.lie import SE3

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]
U8 = NDArray[np.uint8]


@dataclass(frozen=True, slots=True)
class CameraResponse:
    """Monotone response G: [0, 1] exposure energy -> [0, 1] intensity, a gamma curve with a linear toe.

    ``G(x) = s x`` for ``x < toe``, ``(1 + c) x^(1/gamma) - c`` above (Rec. 709 form), with ``c`` and
    ``s`` chosen so that G is C1 and G(1) = 1. ``gamma = 1`` is linear.
    """

    gamma: float = 1.0
    toe: float = 0.018

    def __post_init__(self) -> None:
        if not (math.isfinite(self.gamma) and 0.2 <= self.gamma <= 5.0):
            raise ShapeError(f"response gamma must be in [0.2, 5], got {self.gamma}")
        if not (0.0 < self.toe < 0.5):
            raise ShapeError(f"response toe must be in (0, 0.5), got {self.toe}")

    def _params(self) -> tuple[float, float]:
        g = 1.0 / self.gamma
        k = self.toe**g * (1.0 - g)
        c = k / (1.0 - k)
        slope = (1.0 + c) * g * self.toe ** (g - 1.0)
        return c, slope

    def curve(self, x: NDArray[np.floating] | float) -> F64:
        """G(x) on values clipped to [0, 1]."""
        xv = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
        if self.gamma == 1.0:
            return xv
        c, slope = self._params()
        return np.where(xv < self.toe, slope * xv, (1.0 + c) * xv ** (1.0 / self.gamma) - c)

    def inverse(self, y: NDArray[np.floating] | float) -> F64:
        """G^-1(y) on values clipped to [0, 1] (closed form)."""
        yv = np.clip(np.asarray(y, dtype=np.float64), 0.0, 1.0)
        if self.gamma == 1.0:
            return yv
        c, slope = self._params()
        y_toe = slope * self.toe
        upper = np.maximum((yv + c) / (1.0 + c), 0.0) ** self.gamma
        return np.where(yv < y_toe, yv / slope, upper)

    def inverse_lut(self) -> F64:
        """(256,) inverse response in the DSO / TUM-monoVO pcalib.txt convention:
        pixel value i in 0..255 -> energy 255 * G^-1(i / 255), increasing from 0 to 255."""
        return np.asarray(255.0 * self.inverse(np.arange(256) / 255.0), dtype=np.float64)


_LUT_N = 65536


@functools.lru_cache(maxsize=16)
def _response_lut(gamma: float, toe: float) -> U8:
    """(65536,) uint8 table of rint(255 G(i / 65535))."""
    lut = np.rint(255.0 * CameraResponse(gamma, toe).curve(np.arange(_LUT_N) / (_LUT_N - 1.0)))
    out = lut.astype(np.uint8)
    out.setflags(write=False)
    return out


@functools.lru_cache(maxsize=16)
def _vignette_map(vignette: RadialVignette, h: int, w: int) -> F32:
    """Read-only float32 (h, w) map of ``vignette`` (the model of amrvio.photometric.model),
    cached: every frame of a run uses the same one."""
    vmap = vignette.map(h, w).astype(np.float32)
    vmap.setflags(write=False)
    return vmap


@dataclass(frozen=True, slots=True)
class SensorModel:
    """Camera sensor: analog gain, response, vignetting, noise and 8-bit quantisation.

    full_well_e: electrons at saturation (shot noise variance = electrons). read_noise_dn: standard
    deviation of the read noise in DN (1/255 of full scale) of the linear signal. noise=False turns
    every noise source off (then the output is a deterministic function of the input).
    """

    gain: float = 1.0
    response: CameraResponse = field(default_factory=CameraResponse)
    vignette: RadialVignette = field(default_factory=lambda: RadialVignette(-0.25))
    full_well_e: float = 10000.0
    read_noise_dn: float = 1.0
    noise: bool = True

    def __post_init__(self) -> None:
        self.vignette.check_physical()
        if not (math.isfinite(self.gain) and self.gain > 0):
            raise ShapeError(f"gain must be positive, got {self.gain}")
        if not (self.full_well_e > 0 and self.read_noise_dn >= 0):
            raise ShapeError("full_well_e must be > 0 and read_noise_dn >= 0")

    @staticmethod
    def ideal(gamma: float = 1.0) -> SensorModel:
        """Noise-free sensor without vignetting (for tests and ground-truth renders)."""
        return SensorModel(1.0, CameraResponse(gamma), RadialVignette(0.0, 0.0, 0.0), noise=False)


def expose(
    irradiance_avg: NDArray[np.floating],
    exposure_s: float,
    sensor: SensorModel,
    rng: np.random.Generator | None,
) -> U8:
    """(H, W) radiance averaged over the exposure -> (H, W) uint8 image (model in the module doc).

    ``rng`` draws the noise (may be None when ``sensor.noise`` is False)."""
    E = np.asarray(irradiance_avg)
    if E.ndim != 2 or E.size == 0:
        raise ShapeError(f"irradiance must be a non-empty (H, W) array, got {E.shape}")
    if not (math.isfinite(exposure_s) and exposure_s > 0):
        raise ShapeError(f"exposure_s must be positive, got {exposure_s}")
    h, w = E.shape
    # Collected energy as a fraction of the full well: t * V(x) * B(x)  (seed §4 photometric model)
    x = E.astype(np.float32) * np.float32(exposure_s)
    x *= _vignette_map(sensor.vignette, h, w)
    if not np.all(np.isfinite(x)) or float(x.min()) < 0.0:
        raise ShapeError("irradiance must be finite and >= 0")
    if sensor.noise:
        if rng is None:
            raise ShapeError("a random generator is required when sensor noise is on")
        # Mean signal after gain; the well saturates at full_well_e (energy 1).
        xs = np.minimum(x, np.float32(1.0))
        y = xs * np.float32(sensor.gain)
        # Shot noise (Poisson, Gaussian approx: var = electrons) and read noise, independent, in
        # one draw: var(y) = gain^2 x / full_well + (read_noise_dn / 255)^2.
        var = xs * np.float32(sensor.gain**2 / sensor.full_well_e)
        var += np.float32((sensor.read_noise_dn / 255.0) ** 2)
        np.sqrt(var, out=var)
        var *= rng.standard_normal((h, w), dtype=np.float32)
        y += var
    else:
        y = np.minimum(x, np.float32(1.0)) * np.float32(sensor.gain)
    np.clip(y, 0.0, 1.0, out=y)
    if sensor.response.gamma == 1.0:
        y *= np.float32(255.0)
        return np.rint(y).astype(np.uint8)
    # G through a 2^16-entry table: input step 1.5e-5, far below one output DN.
    idx = (y * np.float32(_LUT_N - 1) + np.float32(0.5)).astype(np.int32)
    out: U8 = np.take(_response_lut(sensor.response.gamma, sensor.response.toe), idx)
    return out


@dataclass(frozen=True, slots=True, eq=False)
class RenderedFrame:
    """One exposed frame. smear_px_*: predicted image-motion path length over the exposure (pixels),
    maximum over the image and at the principal point, while light was collected.
    T_world_cam_mid: pose at mid-exposure. open_fraction: the share of the exposure during which
    the lens was not covered (1 normally, 0 for a frame exposed inside a black-out)."""

    image: U8
    n_subframes: int
    smear_px_max: float
    smear_px_center: float
    T_world_cam_mid: SE3
    t_mid_s: float
    exposure_s: float
    open_fraction: float = 1.0


@functools.lru_cache(maxsize=8)
def _smear_grid(camera: CameraModel, step: int) -> tuple[NDArray[np.intp], NDArray[np.intp], F64,
                                                          int]:
    """Sample pixels (every ``step``), their rays (z = 1) and the index of the one nearest the
    principal point."""
    us = np.arange(step // 2, camera.width, step)
    vs = np.arange(step // 2, camera.height, step)
    uu, vv = np.meshgrid(us, vs)
    uv = np.stack([uu.ravel(), vv.ravel()], axis=1).astype(np.float64)
    centre = np.array([[round(camera.cx), round(camera.cy)]], dtype=np.float64)
    centre = np.clip(centre, 0, [camera.width - 1, camera.height - 1])
    uv = np.concatenate([centre, uv])
    rays = camera.unproject(uv)
    return uv[:, 0].astype(np.intp), uv[:, 1].astype(np.intp), rays, 0


def predict_smear(
    camera: CameraModel,
    depth_mid: NDArray[np.floating],
    T_world_cam_mid: SE3,
    poses: list[SE3],
    step: int = 16,
) -> tuple[float, float]:
    """Image-motion path length (pixels) of the scene points seen at mid-exposure, following the
    camera through ``poses`` (in time order across the exposure). Returns (max, at the principal
    point). Points at infinite depth move by rotation only (homogeneous point [ray, 1/z])."""
    if len(poses) < 2:
        return 0.0, 0.0
    cu, cv_, rays, ic = _smear_grid(camera, step)
    z = np.asarray(depth_mid, dtype=np.float64)[cv_, cu]
    ok = np.all(np.isfinite(rays), axis=1)
    inv_z = np.where(np.isfinite(z) & (z > 0), 1.0 / np.where(z > 0, z, 1.0), 0.0)
    T_cam_world_list = [p.inverse() for p in poses]
    prev: F64 | None = None
    length = np.zeros(rays.shape[0])
    for T_cw in T_cam_world_list:
        T_k_mid = T_cw @ T_world_cam_mid
        # Homogeneous point (ray, 1/z): X_k = R ray + t / z  (scaled by 1/z, same projection)
        Xk = rays @ T_k_mid.R.T + inv_z[:, None] * T_k_mid.t[None, :]
        front = Xk[:, 2] > 1e-9
        ok &= front
        Xk[~front] = [0.0, 0.0, 1.0]
        px = camera.project(Xk)
        ok &= np.all(np.isfinite(px), axis=1)
        if prev is not None:
            step_len = np.linalg.norm(px - prev, axis=1)
            length += np.where(np.isfinite(step_len), step_len, 0.0)
        prev = px
    if not np.any(ok):
        return 0.0, 0.0
    return float(length[ok].max()), float(length[ic]) if ok[ic] else 0.0


def _integrate(
    renderer: SceneRenderer,
    pose_at: Callable[[float], SE3],
    t_start_s: float,
    dur_s: float,
    blur: bool,
    max_subframe_px: float,
    max_subframes: int,
) -> tuple[F32, int, float, float]:
    """Radiance canvas averaged over [t_start_s, t_start_s + dur_s] (sub-frame count from the
    smear, see render_frame), the sub-frame count and the smear (max, at the principal point)."""
    T_mid = pose_at(t_start_s + 0.5 * dur_s)
    canvas, inv_z = renderer.canvas_irradiance(T_mid)
    depth = renderer.finish_depth(inv_z)
    n_path = 8
    path = [pose_at(t_start_s + dur_s * k / n_path) for k in range(n_path + 1)]
    smear_max, smear_center = predict_smear(renderer.camera, depth, T_mid, path)
    n = 1
    if blur and smear_max > 0.0:
        n = math.ceil(smear_max / max_subframe_px) + 1
        n = min(n + (1 - n % 2), max_subframes if max_subframes % 2 else max_subframes - 1)
        n = max(n, 1)
    if n > 1:
        acc = np.zeros(canvas.shape, np.float64)
        for i in range(n):
            if 2 * i + 1 == n:
                acc += canvas  # the mid sub-frame
            else:
                acc += renderer.canvas_irradiance(pose_at(t_start_s + dur_s * (i + 0.5) / n))[0]
        canvas = (acc / n).astype(np.float32)
    return canvas, n, smear_max, smear_center


def render_frame(
    renderer: SceneRenderer,
    pose_at: Callable[[float], SE3],
    t_start_s: float,
    exposure_s: float,
    sensor: SensorModel,
    rng: np.random.Generator | None,
    blur: bool = True,
    max_subframe_px: float = 0.5,
    max_subframes: int = 257,
    lens_covered: Sequence[tuple[float, float]] = (),
) -> RenderedFrame:
    """Render and expose one frame over ``[t_start_s, t_start_s + exposure_s]``.

    ``pose_at(t)`` gives T_world_cam at time t (seconds). With ``blur`` the radiance is the average
    of ``n`` sub-frame renders at the midpoints of n equal sub-intervals (seed §5 temporal
    integral), with ``n = ceil(smear / max_subframe_px) + 1`` made odd (the mid-exposure render is
    reused), capped at ``max_subframes``. Without blur: one render at mid-exposure.
    ``lens_covered``: time intervals [a, b) during which no light reaches the sensor (a covered
    lens, amrvio.sim.blackout); the collected energy is the integral over the uncovered parts only
    (each integrated as above), so a frame exposed inside them is the response to zero irradiance:
    read noise only.
    """
    if not (math.isfinite(exposure_s) and exposure_s > 0):
        raise ShapeError(f"exposure_s must be positive, got {exposure_s}")
    if max_subframe_px <= 0 or max_subframes < 1:
        raise ShapeError("max_subframe_px must be > 0 and max_subframes >= 1")
    t_mid = t_start_s + 0.5 * exposure_s
    pieces = open_pieces(t_start_s, exposure_s, lens_covered)
    if pieces == [(t_start_s, exposure_s)]:  # the lens is open over the whole exposure
        canvas, n, smear_max, smear_center = _integrate(renderer, pose_at, t_start_s, exposure_s, blur,
                                                        max_subframe_px, max_subframes)
        irradiance = renderer.finish_irradiance(canvas)
        open_fraction = 1.0
    else:
        acc: F32 | None = None
        n, smear_max, smear_center, open_s = 0, 0.0, 0.0, 0.0
        for a, d in pieces:
            c, k, s_max, s_center = _integrate(renderer, pose_at, a, d, blur, max_subframe_px,
                                               max_subframes)
            # energy of the piece = its mean radiance x its duration (the exposure is applied below)
            part = c * np.float32(d / exposure_s)
            acc = part if acc is None else acc + part
            n, open_s = n + k, open_s + d
            smear_max, smear_center = max(smear_max, s_max), max(smear_center, s_center)
        cam = renderer.camera
        irradiance = (np.zeros((cam.height, cam.width), np.float32) if acc is None
                      else renderer.finish_irradiance(acc))
        open_fraction = open_s / exposure_s
    image = expose(irradiance, exposure_s, sensor, rng)
    return RenderedFrame(image, n, smear_max, smear_center, pose_at(t_mid), t_mid, exposure_s,
                         open_fraction)
