"""Pyramidal Lucas-Kanade tracking (Bouguet 2000, OpenCV ``calcOpticalFlowPyrLK``).

``LkTracker(config).track(prev, cur, pts) -> TrackResult``. The brightness invariance is a
setting (:class:`~amrvio.tracking.brightness.Invariance`); a forward-backward check (track back
and compare), an LK residual bound and an epipolar check (essential matrix with K, else the
fundamental matrix, by USAC MAGSAC++) reject bad tracks; predicted positions, when given, are the
initial guess. Wide images may be tracked on a coarser pyramid level (``max_width_px``); results
are always in full-resolution pixels.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ShapeError
from amrvio.tracking.brightness import (
    AffineBrightness,
    Invariance,
    affine_from_quantiles,
    image_quantiles,
    normalise_for_tracking,
)

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]
U8 = NDArray[np.uint8]


@dataclass(frozen=True, slots=True)
class EpipolarConfig:
    """Epipolar outlier rejection. It runs when at least ``min_points`` tracks pass the other
    checks and their median flow exceeds ``min_median_flow_px`` (else the geometry is degenerate).
    ``thresh_px``: RANSAC threshold; ``seed``: OpenCV's RNG seed, set before each run."""

    thresh_px: float = 1.0
    min_points: int = 15
    min_median_flow_px: float = 1.0
    seed: int = 0


@dataclass(frozen=True, slots=True)
class LkConfig:
    """Tracker settings (pixels).

    ``win_size``, ``pyr_levels``: LK window and pyramid depth; ``max_iterations``, ``epsilon``:
    the per-level stopping rule. ``fb_thresh_px``: forward-backward error bound (None: no
    backward pass). ``max_error``: bound on LK's mean absolute patch residual (None: none).
    ``border_px``: tracks ending closer to the edge are dropped (``border <= x < w - border``).
    ``epipolar``: None for no epipolar check. ``max_width_px``: wider images are tracked on the
    first pyramid level narrower than it (None: full resolution). ``fb_pyr_levels``: pyramid
    levels of the backward pass (None: ``pyr_levels``); it starts where the point came from, so
    a consistent track needs no coarse level, and each level costs a full window per point.
    ``reduce_by_area``: the ``max_width_px`` reduction averages 2x2 blocks (cv2.INTER_AREA,
    a fifth of ``cv2.pyrDown``'s time) instead of Gaussian smoothing first. Points still map
    as ``p / scale``, so a reduced pixel stands for a full-resolution point 0.5 px (per level,
    times the scale) from its block's centre: the same in both frames, so displacements, and
    the corresponding patches built from them, are unchanged.
    """

    invariance: Invariance = Invariance.AFFINE
    win_size: int = 21
    pyr_levels: int = 3
    max_iterations: int = 30
    epsilon: float = 0.01
    fb_thresh_px: float | None = 1.0
    max_error: float | None = None
    border_px: float = 4.0
    epipolar: EpipolarConfig | None = field(default_factory=EpipolarConfig)
    max_width_px: int | None = None
    fb_pyr_levels: int | None = None
    reduce_by_area: bool = False


@dataclass(frozen=True, slots=True, eq=False)
class TrackImage:
    """An image prepared once for tracking: ``raw`` (H, W) uint8, and ``lk`` the image LK runs
    on (normalised in ``normalise`` mode, and reduced ``levels`` times by ``cv2.pyrDown``)."""

    raw: U8
    lk: U8
    levels: int = 0

    @property
    def scale(self) -> int:
        """Full-resolution pixels per ``lk`` pixel."""
        return 2**self.levels


@dataclass(frozen=True, slots=True)
class TrackResult:
    """Tracked positions (N, 2) for the N input points; ``ok``: (N,) bool; the brightness
    change used (identity unless ``affine``); ``n_fb_rejected`` and ``n_epi_rejected`` count the
    rejections by each check."""

    pts: F64
    ok: NDArray[np.bool_]
    brightness: AffineBrightness
    n_fb_rejected: int
    n_epi_rejected: int


class LkTracker:
    """Tracks points from one image to another. No state between calls apart from the config
    and a memo of the intensity quantiles of the last images seen (a streaming caller passes
    each image twice: as the current one, then as the previous one)."""

    def __init__(self, config: LkConfig | None = None) -> None:
        self.config = config or LkConfig()
        self._quantiles: list[tuple[U8, bytes, F64]] = []

    def _image_quantiles(self, img: U8) -> F64:
        """``image_quantiles(img)``, reused for the same array object with the same sampled
        pixels (a caller that refills one buffer gets fresh quantiles)."""
        probe = img[::7, ::11].tobytes()
        for seen, seen_probe, q in self._quantiles:
            if seen is img and seen_probe == probe:
                return q
        q = image_quantiles(img)
        self._quantiles = [*self._quantiles[-1:], (img, probe, q)]
        return q

    def prepare(self, image: U8) -> TrackImage:
        """Prepare an (H, W) uint8 image once (a streaming caller keeps the previous one)."""
        img = np.asarray(image)
        if img.ndim != 2 or img.dtype != np.uint8:
            raise ShapeError(f"expected an (H, W) uint8 image, got {img.shape} {img.dtype}")
        cfg = self.config
        levels = reduction_levels(img.shape[1], cfg.max_width_px)
        lk = normalise_for_tracking(img) if cfg.invariance is Invariance.NORMALISE else img
        return TrackImage(img, reduced(lk, levels, cfg.reduce_by_area), levels)

    def track(
        self,
        prev: TrackImage | U8,
        cur: TrackImage | U8,
        pts_prev: NDArray[np.floating],
        *,
        pts_pred: NDArray[np.floating] | None = None,
        K: F64 | None = None,
    ) -> TrackResult:
        """Track (N, 2) ``pts_prev`` of ``prev`` into ``cur``. ``pts_pred``: (N, 2) initial guess
        (a motion prior). ``K``: 3x3 intrinsics for the essential-matrix check (else the
        fundamental matrix is used)."""
        cfg = self.config
        p_prev = np.asarray(pts_prev)
        n = len(p_prev)
        if p_prev.shape != (n, 2) or (pts_pred is not None and np.shape(pts_pred) != (n, 2)):
            raise ShapeError("track: pts_prev and pts_pred must be (N, 2)")
        if n == 0:
            return TrackResult(np.zeros((0, 2)), np.zeros(0, dtype=bool), AffineBrightness(), 0, 0)
        a = prev if isinstance(prev, TrackImage) else self.prepare(prev)
        b = cur if isinstance(cur, TrackImage) else self.prepare(cur)
        if a.raw.shape != b.raw.shape or a.levels != b.levels:
            raise ShapeError(f"images differ in shape: {a.raw.shape} vs {b.raw.shape}")
        bright = AffineBrightness()
        ref = a.lk
        if cfg.invariance is Invariance.AFFINE:
            bright = affine_from_quantiles(self._image_quantiles(a.raw),
                                           self._image_quantiles(b.raw))
            ref = a.lk if bright.is_identity() else bright.apply(a.lk)
        s = a.scale
        win = (cfg.win_size, cfg.win_size)
        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, cfg.max_iterations, cfg.epsilon)
        p0 = _to_lk(p_prev, s)
        flags = 0
        if pts_pred is not None:
            p1 = _to_lk(np.asarray(pts_pred), s).copy()
            flags = cv2.OPTFLOW_USE_INITIAL_FLOW
        else:
            p1 = p0.copy()
        p1, st, err = cv2.calcOpticalFlowPyrLK(ref, b.lk, p0, p1, winSize=win,
                                               maxLevel=cfg.pyr_levels, criteria=crit, flags=flags)
        ok = st.ravel() == 1
        if cfg.max_error is not None:
            ok &= err.ravel() < cfg.max_error
        p1s = p1.reshape(-1, 2).astype(np.float64)  # LK-image pixels
        h, w = b.lk.shape
        bd = cfg.border_px / s
        ok &= (p1s[:, 0] >= bd) & (p1s[:, 0] < w - bd) & (p1s[:, 1] >= bd) & (p1s[:, 1] < h - bd)
        p1f = p1s if s == 1 else p1s * s
        ok &= np.isfinite(p1f).all(axis=1)
        n_fb = 0
        if cfg.fb_thresh_px is not None:
            fb_levels = cfg.pyr_levels if cfg.fb_pyr_levels is None else cfg.fb_pyr_levels
            pb, stb, _ = cv2.calcOpticalFlowPyrLK(b.lk, ref, p1, p0.copy(), winSize=win,
                                                  maxLevel=fb_levels, criteria=crit,
                                                  flags=cv2.OPTFLOW_USE_INITIAL_FLOW)
            ok &= stb.ravel() == 1
            fb = np.linalg.norm(_from_lk(pb.reshape(-1, 2), s) - p_prev, axis=1)
            ok_klt = ok.copy()
            ok &= fb < cfg.fb_thresh_px
            n_fb = int((ok_klt & ~ok).sum())
        n_epi = 0
        if cfg.epipolar is not None:
            n_epi = _epipolar_reject(np.asarray(p_prev, np.float64), p1f, ok, cfg.epipolar, K)
        return TrackResult(p1f, ok, bright, n_fb, n_epi)


def reduction_levels(width: int, max_width_px: int | None) -> int:
    """Pyramid levels an image ``width`` pixels wide is reduced by before LK runs on it: the
    first level at most ``max_width_px`` wide (0 for None); the tracked pixel is ``2**levels``
    image pixels."""
    levels = 0
    if max_width_px is not None:
        while (int(width) >> levels) > max_width_px:
            levels += 1
    return levels


def reduced(img: U8, levels: int, by_area: bool = False) -> U8:
    """``img`` halved ``levels`` times, as the tracker reduces wide images: ``cv2.pyrDown``, or
    2x2 means (``cv2.INTER_AREA``) with ``by_area``."""
    for _ in range(levels):
        if by_area:
            img = np.asarray(cv2.resize(img, ((img.shape[1] + 1) // 2, (img.shape[0] + 1) // 2),
                                        interpolation=cv2.INTER_AREA), dtype=np.uint8)
        else:
            img = np.asarray(cv2.pyrDown(img), dtype=np.uint8)
    return img


def _to_lk(p: NDArray[np.floating], scale: int) -> F32:
    """(N, 2) full-resolution pixels -> (N, 1, 2) float32 pixels of the LK image."""
    q = p if scale == 1 else p / scale
    return np.asarray(q, dtype=np.float32).reshape(-1, 1, 2)


def _from_lk(p: F32, scale: int) -> F64:
    """(N, 2) float32 pixels of the LK image -> float64 full-resolution pixels."""
    q = p.astype(np.float64)
    return q if scale == 1 else q * scale


def _epipolar_reject(p0: F64, p1: F64, ok: NDArray[np.bool_], cfg: EpipolarConfig,
                     K: F64 | None) -> int:
    """Clear ``ok`` (in place) for the epipolar outliers among the tracks it holds; their count."""
    if int(ok.sum()) < cfg.min_points:
        return 0
    idx = np.flatnonzero(ok)
    flow = np.linalg.norm(p1[idx] - p0[idx], axis=1)
    if float(np.median(flow)) <= cfg.min_median_flow_px:
        return 0
    cv2.setRNGSeed(cfg.seed)
    if K is not None:  # essential matrix, USAC (MAGSAC++)
        F, m = cv2.findEssentialMat(p0[idx], p1[idx], K, cv2.USAC_MAGSAC, 0.999, cfg.thresh_px)
    else:
        F, m = cv2.findFundamentalMat(p0[idx], p1[idx], cv2.USAC_MAGSAC, cfg.thresh_px, 0.999, 200)
    if F is None or m is None or F.shape != (3, 3):
        return 0
    bad = idx[m.ravel() == 0]
    ok[bad] = False
    return len(bad)


__all__ = [
    "EpipolarConfig",
    "LkConfig",
    "LkTracker",
    "TrackImage",
    "TrackResult",
    "reduction_levels",
]
