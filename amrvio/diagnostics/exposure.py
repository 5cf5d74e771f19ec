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
from dataclasses import dataclass, field

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
from amrvio.tracking.brightness import Invariance
from amrvio.tracking.detect import DetectorConfig, detect_corners
from amrvio.tracking.lk import LkConfig, LkTracker

F32 = NDArray[np.float32]
U8 = NDArray[np.uint8]


def _detector() -> DetectorConfig:
    return DetectorConfig(max_corners=100, quality_level=0.01, min_distance_px=12, block_size=5)


def _lk() -> LkConfig:
    return LkConfig(invariance=Invariance.NORMALISE, win_size=11, pyr_levels=3, max_iterations=20,
                    epsilon=0.03, fb_thresh_px=None, max_error=30.0, border_px=0.0, epipolar=None)


@dataclass(frozen=True, slots=True)
class TrackingConfig:
    """Feature tracking for the exposure fit (and the parallax): ``detector`` (100 Shi-Tomasi
    corners, 12 px apart) and ``lk`` (normalised images, so that the tracker is not fooled by the
    exposure change it measures; 11 px windows, 3 levels, LK residual below 30)."""

    detector: DetectorConfig = field(default_factory=_detector)
    lk: LkConfig = field(default_factory=_lk)


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


def tracker_mask(mask: U8 | None, shape_hw: tuple[int, int], levels: int) -> U8 | None:
    """A full-resolution detection mask reduced to a tracking image ``levels`` pyramid levels
    down, of shape ``shape_hw`` (every second row and column per level); None if it won't fit."""
    for _ in range(levels):
        mask = None if mask is None else np.asarray(mask[::2, ::2])
    if mask is not None and mask.shape != shape_hw:
        mask = np.ascontiguousarray(mask[: shape_hw[0], : shape_hw[1]])
        if mask.shape != shape_hw:
            mask = None
    return mask


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
    tracking: TrackingConfig | None = None,
    inverse_response: NDArray[np.floating] | None = None,
) -> ExposureChange:
    """Stand-alone exposure change between two grey frames: KLT patches, else same pixels.

    (``FrameDiagnostics`` keeps the tracks between frames instead of detecting every time.)
    """
    cfg = cfg or ExposureConfig()
    tracking = tracking or TrackingConfig()
    p, c = np.asarray(prev), np.asarray(cur)
    _check_grey(p, "prev")
    _check_grey(c, "cur")
    if p.shape != c.shape:
        raise ShapeError(f"images differ in shape: {p.shape} vs {c.shape}")
    tracker = LkTracker(tracking.lk)
    t0, t1 = tracker.prepare(p), tracker.prepare(c)
    f0 = prepare_exposure_frame(p, cfg, inverse_response)
    mask = detection_mask(f0)
    pts0 = detect_corners(t0.lk, tracking.detector, mask=tracker_mask(mask, t0.lk.shape, t0.levels))
    pts0 = pts0 * t0.scale
    res = tracker.track(t0, t1, pts0)
    if int(res.ok.sum()) >= cfg.min_tracks:
        f1 = prepare_exposure_frame(c, cfg, inverse_response)
        return fit_exposure_frames(f0, f1, pts0[res.ok], res.pts[res.ok], cfg)
    return fit_exposure_same_pixel(p, c, cfg, inverse_response)
