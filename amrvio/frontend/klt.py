"""The VO's KLT front-end on :mod:`amrvio.tracking`: bucketed corner detection, pyramidal LK with
affine brightness compensation (or none), a forward-backward check and essential-matrix outlier
rejection (USAC), plus the VO's motion prior :func:`predict_tracks`."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ShapeError
from amrvio.geometry.projection import project
from amrvio.tracking.brightness import Invariance
from amrvio.tracking.detect import DetectorConfig, detect_corners
from amrvio.tracking.lk import EpipolarConfig, LkConfig, LkTracker, TrackResult

F64 = NDArray[np.float64]
U8 = NDArray[np.uint8]

KltResult = TrackResult  # the VO's name for a tracking result


def _vo_detector() -> DetectorConfig:
    return DetectorConfig(max_corners=1500, quality_level=0.001, min_distance_px=10, block_size=5,
                          border_px=8, grid_rows=6, grid_cols=16)


@dataclass(frozen=True, slots=True)
class KltConfig:
    """Front-end settings (pixels). ``detector``: bucketed corners; its ``max_corners`` is the
    number of tracks kept alive and its ``border_px`` the detection margin (tracks may come within
    half of it). ``wide_pyr_levels``: pyramid depth after blur or a gap. ``photometric``: affine
    brightness compensation (else none). ``ransac_thresh_px``: essential-matrix outlier gate.
    ``max_width_px``: wider images (HD video) are tracked on the first pyramid level narrower
    than this, positions staying in full-resolution pixels (None: full resolution).
    ``fb_pyr_levels``: pyramid levels of the forward-backward check's backward pass (None: as
    the forward pass). ``guided_retrack``: when KLT lost more of the tracks with a map point than
    PnP kept (a motion prediction wrong for part of the view: the turn of KITTI 00 taken with
    every third frame kept 12-57 PnP inliers of 80-210 such tracks), the lost ones are tracked
    again from their projections at the pose PnP found (:func:`retrack_projected`) and PnP runs
    on all of them; the second pose is kept when it has more inliers."""

    detector: DetectorConfig = field(default_factory=_vo_detector)
    win_size: int = 21
    pyr_levels: int = 3
    wide_pyr_levels: int = 5
    fb_thresh_px: float = 1.0
    photometric: bool = True
    ransac_thresh_px: float = 1.0
    max_iterations: int = 30  # 15 measured: KITTI alike, sim corridor 0.13 -> 0.75 % ATE
    max_width_px: int | None = 1280
    # 0 (full resolution only) costs a quarter, but lets occluded points through (tests)
    fb_pyr_levels: int | None = None
    guided_retrack: bool = True

    @property
    def max_features(self) -> int:
        return self.detector.max_corners

    def lk(self, wide: bool = False, seed: int = 0) -> LkConfig:
        return LkConfig(
            invariance=Invariance.AFFINE if self.photometric else Invariance.NONE,
            win_size=self.win_size,
            pyr_levels=self.wide_pyr_levels if wide else self.pyr_levels,
            max_iterations=self.max_iterations, epsilon=0.01, fb_thresh_px=self.fb_thresh_px,
            max_error=None, border_px=self.detector.border_px * 0.5,
            epipolar=EpipolarConfig(thresh_px=self.ransac_thresh_px, seed=seed),
            max_width_px=self.max_width_px, fb_pyr_levels=self.fb_pyr_levels,
        )


def detect_bucketed(img: U8, existing_px: F64, n_wanted: int, config: KltConfig) -> F64:
    """Shi-Tomasi corners spread over a grid: at most ``n_wanted`` new (M, 2) pixel corners,
    kept away from ``existing_px`` (N, 2) and balanced per cell (strongest first)."""
    return detect_corners(img, config.detector, n_wanted=n_wanted, existing_px=existing_px)


def predict_tracks(K: F64, T_cam_world_pred: F64, R_cur_prev: F64, pts: F64,
                   points_world: F64, has_point: NDArray[np.bool_],
                   shape_hw: tuple[int, int]) -> F64:
    """Motion prior for KLT: (N, 2) predicted positions of (N, 2) ``pts``. Tracks with a map
    point (``has_point``, (N, 3) ``points_world``) are projected with the predicted pose; the
    others follow the rotation-only homography K R K^-1 (H&Z 8.4.2). Clipped to the image."""
    n = len(pts)
    if pts.shape != (n, 2) or points_world.shape != (n, 3) or has_point.shape != (n,):
        raise ShapeError("predict_tracks: pts (N, 2), points_world (N, 3), has_point (N,)")
    pred = pts.copy()
    if has_point.any():
        uv, z = project(K, T_cam_world_pred, points_world[has_point])
        ok = z > 0
        sub = pred[has_point]
        sub[ok] = uv[ok]
        pred[has_point] = sub
    rest = ~has_point
    if rest.any():
        Hm = K @ R_cur_prev @ np.linalg.inv(K)
        ph = np.column_stack([pts[rest], np.ones(int(rest.sum()))]) @ Hm.T
        pred[rest] = ph[:, :2] / ph[:, 2:3]
    h, w = shape_hw
    pred[:, 0] = np.clip(pred[:, 0], 0, w - 1)
    pred[:, 1] = np.clip(pred[:, 1], 0, h - 1)
    return pred


class KltTracker:
    """Tracks points from one image to the next. Stateless between calls apart from config;
    ``seed`` seeds the essential-matrix RANSAC."""

    def __init__(self, config: KltConfig | None = None, seed: int = 0) -> None:
        self.config = config or KltConfig()
        self.seed = seed
        self._narrow = LkTracker(self.config.lk(wide=False, seed=seed))
        self._wide = LkTracker(self.config.lk(wide=True, seed=seed))

    def track(
        self,
        img_prev: U8,
        img_cur: U8,
        pts_prev: F64,
        *,
        pts_pred: F64 | None = None,
        wide: bool = False,
        K: F64 | None = None,
        epipolar_check: bool = True,
    ) -> TrackResult:
        """Track (N, 2) ``pts_prev`` into ``img_cur``; ``pts_pred`` is an (N, 2) initial guess
        (from a motion prior). ``wide`` uses a deeper pyramid (after blur or a gap)."""
        tracker = self._wide if wide else self._narrow
        if not epipolar_check:
            tracker = LkTracker(replace(tracker.config, epipolar=None))
        return tracker.track(img_prev, img_cur, pts_prev, pts_pred=pts_pred, K=K)


def retrack_projected(klt: KltTracker, img_prev: U8, img_cur: U8, res: KltResult, lost: NDArray[np.bool_],
                      points_world: F64, K: F64, T_cam_world: F64, pts_prev: F64) -> KltResult:
    """``res`` with its tracks ``lost`` ((N,) of the (N, 2) ``pts_prev``; their map points
    ``points_world``, (L, 3)) tracked again from their projections at ``T_cam_world``, those in
    front of the camera; no epipolar check (PnP judges them). Each keeps the forward-backward
    check."""
    uv, z = project(K, T_cam_world, points_world)
    front = z > 0
    idx = np.flatnonzero(lost)[front]
    again = klt.track(img_prev, img_cur, pts_prev[idx], pts_pred=uv[front], K=K, epipolar_check=False)
    pts, ok = res.pts.copy(), res.ok.copy()
    pts[idx[again.ok]] = again.pts[again.ok]
    ok[idx[again.ok]] = True
    return replace(res, pts=pts, ok=ok)


__all__ = ["KltConfig", "KltResult", "KltTracker", "detect_bucketed", "predict_tracks", "retrack_projected"]
