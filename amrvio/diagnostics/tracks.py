"""The diagnostics' own sparse tracks, made to survive the exposure change they help measure.

LK assumes constant brightness. Under an exposure step the reference image is first mapped into
the brightness of the current one, ``I_ref -> clip(a I_ref + b)``, with (a, b) fitted to the two
images' intensity quantiles (:func:`~amrvio.tracking.brightness.affine_from_quantiles`, clipped
quantiles left out). The mapping clips where the camera clips, so a region that saturates in the
current frame saturates in the mapped reference too and the two images agree there as well.
(Normalising each image to zero mean and unit variance, the alternative, does not: once a fifth
of the image clips, mean and variance no longer follow the affine change, and on KITTI 00 with a
1.5x gain step 40 % of the tracks moved by more than a pixel.)

The quantiles come from a 256-bin histogram of the raw frame, so a frame costs one ``calcHist``
and a mapped pair one table look-up.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import cv2
import numpy as np
from numpy.typing import NDArray

from amrvio.tracking.brightness import QUANTILES, AffineBrightness, Invariance, affine_from_quantiles
from amrvio.tracking.detect import DetectorConfig
from amrvio.tracking.lk import LkConfig, LkTracker, TrackImage, TrackResult, reduction_levels

F64 = NDArray[np.float64]
U8 = NDArray[np.uint8]


def _detector() -> DetectorConfig:
    return DetectorConfig(max_corners=100, quality_level=0.01, min_distance_px=12, block_size=5)


def _lk() -> LkConfig:
    # raw intensities: the brightness change is removed by mapping the reference (see module).
    # Images wider than 640 px are tracked on a reduced level (see diagnostics_tracker)
    return LkConfig(invariance=Invariance.NONE, win_size=11, pyr_levels=3, max_iterations=20,
                    epsilon=0.03, fb_thresh_px=None, max_error=30.0, border_px=0.0, epipolar=None,
                    max_width_px=640, reduce_by_area=True)


@dataclass(frozen=True, slots=True)
class TrackingConfig:
    """Feature tracking for the exposure fit (and the parallax): ``detector`` (100 Shi-Tomasi
    corners, 12 px apart) and ``lk`` (11 px windows, 3 levels, LK residual below 30, images
    wider than 640 px on a reduced level: :func:`diagnostics_tracker`). The tracker
    runs on raw intensities, the reference mapped into the current frame's brightness."""

    detector: DetectorConfig = field(default_factory=_detector)
    lk: LkConfig = field(default_factory=_lk)


def diagnostics_tracker(config: TrackingConfig, width: int) -> LkTracker:
    """The LK tracker for frames ``width`` px wide. A frame wider than ``lk.max_width_px`` is
    tracked on the first pyramid level narrower than it, and the pyramid above that level loses
    as many levels, so that its coarsest level, and with it the reach of a track, is that of the
    full-resolution pyramid. At 752x480 this costs about half of tracking at full resolution (9 px
    windows at full resolution cost 25 % less but made the parallax flag miss standstills: ROC
    AUC 0.85 against 0.95 on the diagnostics-truth suite, 376x240); 11 px windows one level down
    (376x240) see what the truth suite's frames show."""
    lk = config.lk
    down = reduction_levels(width, lk.max_width_px)
    return LkTracker(replace(lk, pyr_levels=max(lk.pyr_levels - down, 1)))


def histogram_quantiles(image: U8) -> F64:
    """The 5, 10, ..., 95 % intensity quantiles (19,) of a uint8 image, from its histogram
    (linear within a grey level, so that the values are not whole numbers)."""
    hist = cv2.calcHist([np.asarray(image)], [0], None, [256], [0, 256]).ravel().astype(np.float64)
    cdf = np.cumsum(hist)
    target = QUANTILES / 100.0 * cdf[-1]
    k = np.searchsorted(cdf, target, side="left")
    below = np.where(k > 0, cdf[np.maximum(k - 1, 0)], 0.0)
    frac = (target - below) / np.maximum(hist[k], 1.0)
    return np.asarray(k + frac - 0.5, dtype=np.float64)


@dataclass(frozen=True, slots=True, eq=False)
class TrackFrame:
    """A frame prepared once for tracking: the LK image and its intensity quantiles (19,)."""

    image: TrackImage
    quantiles: F64


def prepare_track_frame(tracker: LkTracker, image: U8) -> TrackFrame:
    """Prepare an (H, W) uint8 frame for :func:`track_between`. The quantiles are those of the
    raw frame, every eighth row (45k pixels at 752x480; every fourth row cost twice as much, and
    the mapping of consecutive KITTI 00 and EuRoC frames moved mid-grey by 0.5 DN in the median,
    3 DN at most): a reduced pyramid level would smear the clip levels into grey ramps that
    read as unclipped quantiles."""
    t = tracker.prepare(image)
    return TrackFrame(t, histogram_quantiles(np.asarray(image)[::8]))


def map_brightness(image: U8, change: AffineBrightness) -> U8:
    """``clip(round(a I + b), 0, 255)`` by a 256-entry table (the image itself if the change is
    the identity)."""
    if change.a == 1.0 and change.b == 0.0:
        return image
    lut = np.clip(np.arange(256, dtype=np.float64) * change.a + change.b + 0.5, 0, 255)
    out: U8 = cv2.LUT(np.asarray(image), lut.astype(np.uint8))
    return out


def track_between(tracker: LkTracker, prev: TrackFrame, cur: TrackFrame,
                  pts_prev: NDArray[np.floating]) -> TrackResult:
    """Track (N, 2) full-resolution points of ``prev`` into ``cur`` after mapping ``prev`` into
    the brightness of ``cur`` (the result's ``brightness`` is the change used)."""
    change = affine_from_quantiles(prev.quantiles, cur.quantiles)
    if change.is_identity():  # LK's window absorbs a few per cent of gain
        change = AffineBrightness()
    p = prev.image
    ref = TrackImage(p.raw, map_brightness(p.lk, change), p.levels)
    res = tracker.track(ref, cur.image, pts_prev)
    return TrackResult(res.pts, res.ok, change, res.n_fb_rejected, res.n_epi_rejected)


def detection_mask(bad: NDArray[np.bool_]) -> U8 | None:
    """uint8 mask (255 = allowed) for feature detection away from clipped pixels (``bad`` True):
    corners on the edge of a saturated sky are strong but useless for the photometric fit. None
    when that would leave less than a quarter of the image."""
    ok = ~bad
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


__all__ = [
    "TrackFrame",
    "TrackingConfig",
    "detection_mask",
    "diagnostics_tracker",
    "histogram_quantiles",
    "map_brightness",
    "prepare_track_frame",
    "track_between",
    "tracker_mask",
]
