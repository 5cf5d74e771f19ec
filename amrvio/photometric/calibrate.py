"""Estimate response, vignetting and exposures from points tracked across frames.

In the spirit of Bergmann, Wang and Cremers (2017, "Online photometric calibration of auto
exposure video"): a scene point j of radiance L_j seen in frame i at pixel x_ij has intensity
``I_ij = 255 G(t_i V(x_ij) L_j)``. We minimise ``sum_ij (255 G(t_i V(x_ij) L_j) - I_ij)^2`` over the
response parameters, the vignetting (v1, v2, v3), the exposures t_i (unless known) and the
radiances L_j with ``scipy.optimize.least_squares`` on a sparse Jacobian (grouped finite
differences). Saturated (>= 250) and under-exposed (<= 5) observations are dropped, and a
Huber loss absorbs tracking outliers.

Gauges: without known exposures, one global scale between t and L is free (t_0 = 1 is fixed).
G is normalised so that energy 1 saturates. With unknown exposures there is also the classic
exponent ambiguity (G(x^(1/g)), t^g, V^g, L^g explain the data equally); the fit then returns
one member of that family and exposures are only meaningful up to it: use known exposures for an
absolute response (the simulator and TUM-monoVO record them).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from amrvio.errors import ShapeError
from amrvio.photometric.model import MonotoneResponse, RadialVignette, bernstein_basis
from amrvio.tracking.brightness import Invariance
from amrvio.tracking.detect import DetectorConfig, detect_corners
from amrvio.tracking.lk import LkConfig, LkTracker, TrackImage

F64 = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class PhotometricObservations:
    """Observations of tracked points: ``frame`` (M,) and ``point`` (M,) indices, ``uv`` (M, 2)
    pixels, ``intensity`` (M,) DN; ``width``/``height`` of the images; ``n_frames``."""

    frame: NDArray[np.int64]
    point: NDArray[np.int64]
    uv: F64
    intensity: F64
    width: int
    height: int
    n_frames: int

    def __post_init__(self) -> None:
        m = np.asarray(self.frame).shape[0]
        if (
            np.asarray(self.point).shape != (m,)
            or np.asarray(self.uv).shape != (m, 2)
            or np.asarray(self.intensity).shape != (m,)
        ):
            raise ShapeError("observations need frame (M,), point (M,), uv (M,2), intensity (M,)")


class CalibrationStatus(enum.Enum):
    OK = "ok"
    TOO_FEW_OBSERVATIONS = "too_few_observations"
    NOT_CONVERGED = "not_converged"


@dataclass(frozen=True, slots=True)
class PhotometricEstimate:
    """Result: ``response`` (G), ``vignette``, ``exposures_s`` (F,) (known ones echoed, unknown
    ones relative with t_0 = 1), ``radiance`` (P,), ``rms_dn`` residual, ``status``."""

    response: MonotoneResponse
    vignette: RadialVignette
    exposures_s: F64
    radiance: F64
    rms_dn: float
    n_observations: int
    status: CalibrationStatus


def _softplus(x: F64) -> F64:
    return np.asarray(np.logaddexp(0.0, x))


def _inv_softplus(y: F64) -> F64:
    return np.asarray(np.log(np.expm1(np.maximum(y, 1e-12))))


def estimate_photometric_calibration(
    obs: PhotometricObservations,
    exposures_s: NDArray[np.floating] | None = None,
    degree: int = 4,
    low_dn: float = 5.0,
    high_dn: float = 250.0,
    max_nfev: int = 200,
    huber_dn: float = 3.0,
) -> PhotometricEstimate:
    """Fit G (monotone Bernstein of ``degree``), radial V and (unless given) exposures."""
    I = np.asarray(obs.intensity, dtype=np.float64)
    keep = (I > low_dn) & (I < high_dn) & np.isfinite(I)
    frame = np.asarray(obs.frame, np.int64)[keep]
    point_raw = np.asarray(obs.point, np.int64)[keep]
    # each point needs >= 2 observations to inform anything but its own radiance
    uniq, inv, counts = np.unique(point_raw, return_inverse=True, return_counts=True)
    multi = counts[inv] >= 2
    frame, I, uv = frame[multi], I[keep][multi], np.asarray(obs.uv, np.float64)[keep][multi]
    _, point = np.unique(point_raw[multi], return_inverse=True)
    n_pts = int(point.max()) + 1 if point.size else 0
    F = obs.n_frames
    known = exposures_s is not None
    if known:
        t_known = np.asarray(exposures_s, dtype=np.float64)
        if t_known.shape != (F,) or np.any(t_known <= 0):
            raise ShapeError(f"exposures_s must be ({F},) and positive")
    M = int(I.size)
    nfree_t = 0 if known else F - 1
    n_params = degree + 4 + nfree_t
    if M < 2 * (n_params + n_pts) or n_pts < 10:
        return PhotometricEstimate(
            MonotoneResponse.linear(degree), RadialVignette(), np.ones(F), np.zeros(n_pts),
            float("nan"), M, CalibrationStatus.TOO_FEW_OBSERVATIONS,
        )
    r2 = RadialVignette.radius(uv, obs.width, obs.height) ** 2
    y = I / 255.0
    grid = np.linspace(0.0, 1.0, 2049)

    def unpack(p: F64) -> tuple[F64, float, F64, F64]:
        inc = _softplus(p[:degree])
        c = np.concatenate([[0.0], np.cumsum(inc) / inc.sum()])
        gamma = float(np.exp(p[degree]))
        v = p[degree + 1 : degree + 4]
        if known:
            logt = np.log(t_known)
        else:
            logt = np.concatenate([[0.0], p[degree + 4 :]])
        return c, gamma, v, logt

    def G(x: F64, c: F64, gamma: float) -> F64:
        # G(x) = P(x^gamma): a gamma curve refined by a monotone Bernstein polynomial P.
        return np.asarray(bernstein_basis(np.clip(x, 0.0, 1.0) ** gamma, degree) @ c)

    def project_radiance(c: F64, gamma: float, a: F64) -> F64:
        # Variable projection: for fixed G, V, t the radiance of each point is the least-squares
        # fit of a_ij L_j to G^-1(y_ij), a_ij = t_i V_ij (closed form per point).
        g = G(grid, c, gamma)
        g = np.maximum.accumulate(g) + grid * 1e-9
        e = np.interp(y, g, grid)  # G^-1(y)
        num = np.bincount(point, weights=a * e, minlength=n_pts)
        den = np.bincount(point, weights=a * a, minlength=n_pts)
        return np.asarray(num / np.maximum(den, 1e-300))

    def model(p: F64) -> tuple[F64, F64]:
        c, gamma, v, logt = unpack(p)
        V = np.maximum(1.0 + r2 * (v[0] + r2 * (v[1] + r2 * v[2])), 1e-6)
        a = np.exp(logt[frame]) * V
        L = project_radiance(c, gamma, a)
        g = G(a * L[point], c, gamma)
        return np.asarray(255.0 * (g - y)), L

    def residuals(p: F64) -> F64:
        return model(p)[0]

    p0 = np.concatenate([_inv_softplus(np.full(degree, 1.0 / degree)), np.zeros(4 + nfree_t)])
    res = least_squares(
        residuals, p0, method="trf", loss="huber", f_scale=huber_dn, x_scale=1.0,
        max_nfev=max_nfev, xtol=1e-10, ftol=1e-10,
    )
    c, gamma, v, logt = unpack(res.x)
    fun, L = model(res.x)
    rms = float(np.sqrt(np.mean(fun**2)))
    status = CalibrationStatus.OK if res.status > 0 else CalibrationStatus.NOT_CONVERGED
    return PhotometricEstimate(
        MonotoneResponse(tuple(float(x) for x in c), gamma),
        RadialVignette(float(v[0]), float(v[1]), float(v[2])),
        np.exp(logt),
        L,
        rms,
        M,
        status,
    )


def track_observations(
    images: list[NDArray[np.uint8]],
    max_points: int = 400,
    min_distance: int = 10,
    win: int = 21,
    patch_radius: int = 1,
) -> PhotometricObservations:
    """KLT-track points through a sequence (on contrast-normalised images, so exposure changes do
    not break tracking) and record the mean intensity of a (2r+1)^2 patch at each position.
    Points lost are replaced by new detections (new point ids). Low-gradient points are preferred
    (minimum-eigenvalue corners at a low quality level, then sorted by the local gradient) because
    their intensity is insensitive to sub-pixel tracking error."""
    if not images:
        raise ShapeError("track_observations needs at least one image")
    h, w = images[0].shape
    tracker = LkTracker(LkConfig(invariance=Invariance.NORMALISE, win_size=win, pyr_levels=3,
                                 fb_thresh_px=None, border_px=2.0, epipolar=None))
    detector = DetectorConfig(max_corners=max_points, quality_level=0.005,
                              min_distance_px=min_distance, block_size=7)
    frames: list[NDArray[np.int64]] = []
    points: list[NDArray[np.int64]] = []
    uvs: list[F64] = []
    vals: list[F64] = []
    next_id = 0
    prev: TrackImage | None = None
    pts = np.zeros((0, 2), np.float32)
    ids = np.zeros(0, np.int64)
    k = np.ones((2 * patch_radius + 1,) * 2, np.float32) / float((2 * patch_radius + 1) ** 2)
    for i, img in enumerate(images):
        if img.shape != (h, w):
            raise ShapeError("all images must have the same size")
        cur = tracker.prepare(img)
        if prev is not None and pts.shape[0]:
            res = tracker.track(prev, cur, pts)
            pts, ids = res.pts[res.ok].astype(np.float32), ids[res.ok]
        if pts.shape[0] < max_points // 2:
            new = detect_corners(cur.lk, detector, n_wanted=max_points - pts.shape[0],
                                 existing_px=pts.astype(np.float64)).astype(np.float32)
            if new.shape[0]:
                pts = np.concatenate([pts, new])
                ids = np.concatenate([ids, np.arange(next_id, next_id + new.shape[0])])
                next_id += new.shape[0]
        if pts.shape[0]:
            smooth = cv2.filter2D(img.astype(np.float32), -1, k)
            v = cv2.remap(smooth, pts[:, 0:1], pts[:, 1:2], cv2.INTER_LINEAR).ravel()
            frames.append(np.full(pts.shape[0], i, dtype=np.int64))
            points.append(ids.copy())
            uvs.append(pts.astype(np.float64))
            vals.append(v.astype(np.float64))
        prev = cur
    return PhotometricObservations(
        np.concatenate(frames).astype(np.int64),
        np.concatenate(points).astype(np.int64),
        np.concatenate(uvs),
        np.concatenate(vals),
        w,
        h,
        len(images),
    )


def fit_response_to_inverse_lut(
    inverse_response: NDArray[np.floating], degree: int = 6, low_dn: int = 5, high_dn: int = 250
) -> tuple[MonotoneResponse, float]:
    """Fit the parametric response to a (256,) DSO inverse response (e.g. a third-party pcalib).

    ``G^-1`` is normalised to 1 at DN 255; the fit minimises ``255 G(G^-1(k)) - k`` over DN
    ``low_dn..high_dn``. Returns the response and the RMS of the inverse curves' difference
    (fraction of full scale) over those DN.
    """
    lut = np.asarray(inverse_response, dtype=np.float64)
    if lut.shape != (256,) or not np.all(np.isfinite(lut)):
        raise ShapeError(f"inverse_response must be (256,) finite, got {lut.shape}")
    e = (lut - lut[0]) / (lut[255] - lut[0])
    k = np.arange(low_dn, high_dn + 1)

    def unpack(p: F64) -> MonotoneResponse:
        inc = _softplus(p[:degree])
        c = np.concatenate([[0.0], np.cumsum(inc) / inc.sum()])
        return MonotoneResponse(tuple(float(x) for x in c), float(np.exp(p[degree])))

    def res(p: F64) -> F64:
        return np.asarray(255.0 * unpack(p).curve(e[k]) - k)

    p0 = np.concatenate([_inv_softplus(np.full(degree, 1.0 / degree)), [0.0]])
    sol = least_squares(res, p0, method="trf", x_scale=1.0, max_nfev=500)
    resp = unpack(sol.x)
    inv = resp.inverse_lut()
    inv = (inv - inv[0]) / (inv[255] - inv[0])
    rms = float(np.sqrt(np.mean((inv[k] - e[k]) ** 2)))
    return resp, rms


def fit_radial_vignette(vignette: NDArray[np.floating], step: int = 4) -> tuple[RadialVignette, float]:
    """Least-squares radial model ``V(r) = 1 + v1 r^2 + v2 r^4 + v3 r^6`` of an (H, W) vignette map
    (e.g. a third-party vignette.png), after scaling the map to 1 at the image centre. Returns the
    model and the RMS difference of the two maps (both normalised to max 1)."""
    v = np.asarray(vignette, dtype=np.float64)
    if v.ndim != 2 or not np.all(np.isfinite(v)) or float(v.max()) <= 0:
        raise ShapeError("vignette must be a finite, positive (H, W) map")
    h, w = v.shape
    vv, uu = np.mgrid[0:h:step, 0:w:step]
    uv = np.stack([uu.ravel(), vv.ravel()], axis=1).astype(np.float64)
    r2 = RadialVignette.radius(uv, w, h) ** 2
    vals = v[vv.ravel(), uu.ravel()]
    # V_map = s * (1 + v1 r^2 + v2 r^4 + v3 r^6): linear in (s, s v1, s v2, s v3)
    A = np.stack([np.ones_like(r2), r2, r2**2, r2**3], axis=1)
    coef = np.linalg.lstsq(A, vals, rcond=None)[0]
    model = RadialVignette(*(float(c / coef[0]) for c in coef[1:]))
    m = model.map(h, w)
    rms = float(np.sqrt(np.mean((m / m.max() - v / v.max()) ** 2)))
    return model, rms
