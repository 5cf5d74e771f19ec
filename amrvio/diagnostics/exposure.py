"""Exposure change between consecutive frames (seed section 4), on corresponding pixels.

When the camera moves, the same pixel in two frames sees different scene points, so the affine fit
``I_cur ~= a I_prev + b`` runs on patches around KLT-tracked features instead. The tracker itself
must not be fooled by the exposure change it is measuring, so it runs on images normalised to zero
mean and unit standard deviation (an affine change of intensity leaves them unchanged, apart from
clipping). When the camera is still (or tracking fails) the fit uses the same pixels on a grid.

EV: ``log2(a)`` is the exposure step when the response is linear and the offset is ~0.
- With the camera's inverse response (DSO pcalib) the fit runs on linearised intensities, where
  the model is a pure scale (the DSO inverse response starts at 0): the offset is fixed to 0 and
  ``ev = log2(a)`` exactly.
- Without it (raw intensities, offset free) we report ``ev = log2((a m + b) / m)``, the gain at
  the median reference intensity ``m``: equal to ``log2(a)`` when ``b ~= 0``, and robust to the
  a/b trade-off (motion blur lowers contrast, which an affine fit explains by a < 1 and b > 0
  while the brightness, and the exposure, did not change). A gamma-like response still compresses
  this EV (by ~1/gamma).
Fits whose gain is beyond +-``max_abs_ev`` are implausible (tracking failure): ``valid=False``,
``ev`` NaN and no flag.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ShapeError
from amrvio.photometric.affine import (
    SATURATED_DN,
    UNDEREXPOSED_DN,
    AffineFit,
    AffineStatus,
    fit_affine_robust,
    linearise,
)

F32 = NDArray[np.float32]
U8 = NDArray[np.uint8]


@dataclass(frozen=True, slots=True)
class TrackerConfig:
    """KLT settings. ``max_corners`` features (``min_distance`` px apart) are detected when fewer
    than ``min_tracks`` survive; pyramidal LK with ``win`` px windows and ``levels`` levels."""

    max_corners: int = 100
    min_tracks: int = 40
    quality: float = 0.01
    min_distance: int = 12
    win: int = 11
    levels: int = 3
    max_error: float = 30.0


@dataclass(frozen=True, slots=True)
class ExposureConfig:
    """``ev_step``: |EV| at or above it flags an exposure step. ``patch_radius``: patches of
    (2r+1)^2 pixels around each tracked point. ``grid_step``: pixel stride of the same-pixel fit.
    ``min_tracks``: below it the same-pixel fit is used. ``max_abs_ev``: larger |EV| is treated
    as a failed fit."""

    ev_step: float = 0.3
    patch_radius: int = 3
    curvature_dn: float = 3.0
    smooth_px: int = 9
    max_abs_ev: float = 4.0
    grid_step: int = 8
    min_tracks: int = 15
    huber_k: float = 1.345


@dataclass(frozen=True, slots=True)
class ExposureChange:
    """Affine brightness change prev -> cur. ``method``: "klt" (tracked patches) or "same_pixel".

    ``ev``: see the module docstring (``log2(a)`` on linearised intensities, the log2 gain at the
    median intensity on raw ones; NaN if the fit failed or is implausible, then ``valid`` is
    False); ``flag``: ``|ev| >= ev_step``.
    """

    fit: AffineFit
    ev: float
    flag: bool
    method: str
    n_tracks: int
    valid: bool = True

    @property
    def a(self) -> float:
        return self.fit.a

    @property
    def b(self) -> float:
        return self.fit.b


def _check_grey(img: NDArray[np.generic], name: str) -> None:
    if img.ndim != 2 or img.shape[0] < 8 or img.shape[1] < 8:
        raise ShapeError(f"{name} must be a (H,W) grey image of at least 8x8, got {img.shape}")


def normalise_for_tracking(image: U8) -> U8:
    """(H, W) uint8 -> uint8 ``128 + 40 (I - mean) / std``: invariant to affine brightness."""
    img = np.asarray(image)
    _check_grey(img, "image")
    mean, std = cv2.meanStdDev(img)
    s = max(float(std[0, 0]), 1e-3)
    alpha = 40.0 / s
    beta = 128.0 - alpha * float(mean[0, 0])
    # addWeighted saturates to 0..255 (no abs, unlike convertScaleAbs).
    out: U8 = cv2.addWeighted(img, alpha, img, 0.0, beta, dtype=cv2.CV_8U)
    return out


def detect_features(norm: U8, cfg: TrackerConfig, mask: U8 | None = None) -> F32:
    """Shi-Tomasi corners on a normalised image -> (N, 2) float32 pixel coordinates."""
    pts = cv2.goodFeaturesToTrack(
        norm, cfg.max_corners, cfg.quality, cfg.min_distance, mask=mask, blockSize=5
    )
    if pts is None:
        return np.zeros((0, 2), np.float32)
    return np.asarray(pts.reshape(-1, 2), dtype=np.float32)


def track_features(prev_norm: U8, cur_norm: U8, pts: F32, cfg: TrackerConfig) -> tuple[
    F32, NDArray[np.bool_]
]:
    """Pyramidal LK from ``prev_norm`` to ``cur_norm`` -> (new (N, 2), ok (N,))."""
    if pts.shape[0] == 0:
        return pts.copy(), np.zeros(0, dtype=bool)
    p1, st, err = cv2.calcOpticalFlowPyrLK(
        prev_norm,
        cur_norm,
        pts.reshape(-1, 1, 2),
        None,
        winSize=(cfg.win, cfg.win),
        maxLevel=cfg.levels,
        criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 20, 0.03),
    )
    p1 = p1.reshape(-1, 2)
    h, w = cur_norm.shape
    ok = (st.ravel() == 1) & (err.ravel() < cfg.max_error)
    ok &= (p1[:, 0] >= 0) & (p1[:, 0] <= w - 1) & (p1[:, 1] >= 0) & (p1[:, 1] <= h - 1)
    return np.asarray(p1, dtype=np.float32), ok


def sample_patches(image: NDArray[np.generic], pts: NDArray[np.floating], radius: int) -> F32:
    """Bilinear samples of (2r+1)^2 patches centred on (N, 2) points -> (N, (2r+1)^2) float32."""
    offs = np.arange(-radius, radius + 1, dtype=np.float32)
    ox, oy = np.meshgrid(offs, offs)
    p = np.asarray(pts, dtype=np.float32)
    mx = (p[:, 0:1] + ox.ravel()[None, :]).astype(np.float32)
    my = (p[:, 1:2] + oy.ravel()[None, :]).astype(np.float32)
    src = np.asarray(image, dtype=np.float32)
    out: F32 = cv2.remap(src, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return out


@dataclass(frozen=True, slots=True, eq=False)
class ExposureFrame:
    """A frame prepared for the patch fit: ``smooth`` (H, W) float32 box-filtered intensity
    (linearised first when an inverse response is given) and ``bad`` (H, W) bool, True where the
    box touches a saturated (>= 250) or under-exposed (<= 5) raw pixel."""

    smooth: F32
    bad: NDArray[np.bool_]
    linear: bool = False  # linearised through an inverse response


def prepare_exposure_frame(
    image: NDArray[np.generic],
    cfg: ExposureConfig | None = None,
    inverse_response: NDArray[np.floating] | None = None,
) -> ExposureFrame:
    """Box-filter a grey frame (``cfg.smooth_px``) for :func:`fit_exposure_frames`. The low-pass
    makes the fit insensitive to motion blur and to sub-pixel resampling, which both smooth
    intensity and would otherwise read as a lower gain."""
    cfg = cfg or ExposureConfig()
    img = np.asarray(image)
    _check_grey(img, "image")
    k = max(1, cfg.smooth_px)
    src = img if inverse_response is None else linearise(img, inverse_response).astype(np.float32)
    if img.dtype != np.uint8:
        img = np.clip(img, 0, 255).astype(np.uint8)
    clipped = cv2.inRange(img, int(UNDEREXPOSED_DN) + 1, int(SATURATED_DN) - 1) == 0
    if k > 1:
        smooth = cv2.boxFilter(src, cv2.CV_32F, (k, k), borderType=cv2.BORDER_REPLICATE)
        bad = cv2.dilate(clipped.view(np.uint8), np.ones((k, k), np.uint8)) > 0
    else:
        smooth, bad = src.astype(np.float32), clipped
    return ExposureFrame(
        np.asarray(smooth, np.float32), np.asarray(bad, bool), inverse_response is not None
    )


def detection_mask(frame: ExposureFrame) -> U8 | None:
    """uint8 mask (255 = allowed) for feature detection away from clipped pixels: corners on the
    edge of a saturated sky are strong but useless for the photometric fit. None when that would
    leave less than a quarter of the image."""
    ok = ~frame.bad
    if float(ok.mean()) < 0.25:
        return None
    return np.asarray(ok, np.uint8) * np.uint8(255)


def fit_exposure_frames(
    prev: ExposureFrame,
    cur: ExposureFrame,
    pts_prev: NDArray[np.floating],
    pts_cur: NDArray[np.floating],
    cfg: ExposureConfig | None = None,
) -> ExposureChange:
    """Robust affine fit on patches around corresponding points (N, 2) of two prepared frames.

    Patches are sampled at integer pixels of ``prev`` and at the matching sub-pixel positions of
    ``cur``; samples whose box touched a clipped raw pixel are masked, and the rest are weighted
    by their local curvature (see :class:`ExposureConfig`).
    """
    cfg = cfg or ExposureConfig()
    p0 = np.asarray(pts_prev, dtype=np.float32)
    p1 = np.asarray(pts_cur, dtype=np.float32)
    if p0.shape != p1.shape or p0.ndim != 2 or p0.shape[1] != 2:
        raise ShapeError(f"point arrays must both be (N,2), got {p0.shape}, {p1.shape}")
    q0 = np.round(p0)
    q1 = p1 + (q0 - p0)
    r = cfg.patch_radius
    x = sample_patches(prev.smooth, q0, r)
    y = sample_patches(cur.smooth, q1, r)
    bad0 = _sample_mask(prev.bad, q0, r)
    bad1 = _sample_mask(cur.bad, q1, r)
    w = _curvature_weights(x, r, cfg.curvature_dn)
    fit = fit_affine_robust(x, y, mask=~(bad0 | bad1), weights=w, huber_k=cfg.huber_k,
                            fit_offset=not (prev.linear and cur.linear))
    return _result(fit, cfg, "klt", int(p0.shape[0]), prev.linear and cur.linear)


def fit_exposure_on_correspondences(
    prev: NDArray[np.generic],
    cur: NDArray[np.generic],
    pts_prev: NDArray[np.floating],
    pts_cur: NDArray[np.floating],
    cfg: ExposureConfig | None = None,
    inverse_response: NDArray[np.floating] | None = None,
) -> ExposureChange:
    """Robust affine fit on patches around corresponding points (N, 2) of ``prev`` and ``cur``.

    Saturated (>= 250) and under-exposed (<= 5) raw samples are masked; with ``inverse_response``
    the fit runs on linearised intensities (see module docstring). Prepares both frames with
    :func:`prepare_exposure_frame` (a streaming caller should cache the previous one).
    """
    return fit_exposure_frames(
        prepare_exposure_frame(prev, cfg, inverse_response),
        prepare_exposure_frame(cur, cfg, inverse_response),
        pts_prev,
        pts_cur,
        cfg,
    )


def _sample_mask(mask: NDArray[np.bool_], pts: NDArray[np.floating], radius: int) -> NDArray[
    np.bool_
]:
    """Nearest-pixel samples of a boolean map on the patch grid (outside the image: True)."""
    offs = np.arange(-radius, radius + 1)
    ox, oy = np.meshgrid(offs, offs)
    u = np.rint(pts[:, 0:1]).astype(np.intp) + ox.ravel()[None, :]
    v = np.rint(pts[:, 1:2]).astype(np.intp) + oy.ravel()[None, :]
    h, w = mask.shape
    inside = (u >= 0) & (u < w) & (v >= 0) & (v < h)
    out = np.ones(u.shape, dtype=bool)
    out[inside] = mask[v[inside], u[inside]]
    return out


def _curvature_weights(x: F32, radius: int, scale_dn: float) -> NDArray[np.float64]:
    # Sub-pixel resampling error ~ (d^2 / 2) * Laplacian: trust flat samples, drop patch borders.
    n = 2 * radius + 1
    p = x.reshape(-1, n, n).astype(np.float64)
    lap = np.zeros_like(p)
    lap[:, 1:-1, 1:-1] = (
        p[:, 2:, 1:-1] + p[:, :-2, 1:-1] + p[:, 1:-1, 2:] + p[:, 1:-1, :-2] - 4.0 * p[:, 1:-1, 1:-1]
    )
    w = 1.0 / (1.0 + (lap / scale_dn) ** 2)
    w[:, 0, :] = w[:, -1, :] = w[:, :, 0] = w[:, :, -1] = 0.0
    return w.reshape(x.shape)


def fit_exposure_same_pixel(
    prev: NDArray[np.generic],
    cur: NDArray[np.generic],
    cfg: ExposureConfig | None = None,
    inverse_response: NDArray[np.floating] | None = None,
) -> ExposureChange:
    """Robust affine fit on the same pixels (every ``grid_step``-th row and column)."""
    cfg = cfg or ExposureConfig()
    a0, a1 = np.asarray(prev), np.asarray(cur)
    if a0.shape != a1.shape:
        raise ShapeError(f"images differ in shape: {a0.shape} vs {a1.shape}")
    s = max(1, cfg.grid_step)
    return _finish(a0[::s, ::s], a1[::s, ::s], cfg, inverse_response, "same_pixel", 0)


def _finish(
    x: NDArray[np.generic],
    y: NDArray[np.generic],
    cfg: ExposureConfig,
    inverse_response: NDArray[np.floating] | None,
    method: str,
    n_tracks: int,
    weights: NDArray[np.float64] | None = None,
) -> ExposureChange:
    xr = np.asarray(x, dtype=np.float64)
    yr = np.asarray(y, dtype=np.float64)
    mask = (xr > UNDEREXPOSED_DN) & (xr < SATURATED_DN) & (yr > UNDEREXPOSED_DN) & (
        yr < SATURATED_DN
    )
    if inverse_response is not None:
        xr = linearise(xr, inverse_response)
        yr = linearise(yr, inverse_response)
    fit = fit_affine_robust(xr, yr, mask=mask, weights=weights, huber_k=cfg.huber_k,
                            fit_offset=inverse_response is None)
    return _result(fit, cfg, method, n_tracks, inverse_response is not None)


def _result(
    fit: AffineFit, cfg: ExposureConfig, method: str, n_tracks: int, linear: bool
) -> ExposureChange:
    ev = float("nan")
    if fit.status is AffineStatus.OK:
        m = fit.x_median
        gain = fit.a if linear or not m > 0 else (fit.a * m + fit.b) / m
        ev = math.log2(gain) if gain > 0 else float("nan")
    valid = bool(math.isfinite(ev) and abs(ev) <= cfg.max_abs_ev)
    if not valid:
        ev = float("nan")
    flag = bool(valid and abs(ev) >= cfg.ev_step)
    return ExposureChange(fit, ev, flag, method, n_tracks, valid)


def saturated_fraction(image: NDArray[np.generic], high: float = SATURATED_DN) -> float:
    """Fraction of pixels at or above ``high`` DN."""
    img = np.asarray(image)
    return float(np.count_nonzero(img >= high)) / float(max(img.size, 1))


def estimate_exposure_change(
    prev: U8,
    cur: U8,
    cfg: ExposureConfig | None = None,
    tracker: TrackerConfig | None = None,
    inverse_response: NDArray[np.floating] | None = None,
) -> ExposureChange:
    """Stand-alone exposure change between two grey frames: KLT patches, else same pixels.

    (``FrameDiagnostics`` keeps the tracks between frames instead of detecting every time.)
    """
    cfg = cfg or ExposureConfig()
    tracker = tracker or TrackerConfig()
    p, c = np.asarray(prev), np.asarray(cur)
    _check_grey(p, "prev")
    _check_grey(c, "cur")
    if p.shape != c.shape:
        raise ShapeError(f"images differ in shape: {p.shape} vs {c.shape}")
    n0, n1 = normalise_for_tracking(p), normalise_for_tracking(c)
    f0 = prepare_exposure_frame(p, cfg, inverse_response)
    pts0 = detect_features(n0, tracker, mask=detection_mask(f0))
    pts1, ok = track_features(n0, n1, pts0, tracker)
    if int(ok.sum()) >= cfg.min_tracks:
        f1 = prepare_exposure_frame(c, cfg, inverse_response)
        return fit_exposure_frames(f0, f1, pts0[ok], pts1[ok], cfg)
    return fit_exposure_same_pixel(p, c, cfg, inverse_response)
