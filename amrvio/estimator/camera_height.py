"""Metric scale from a known camera height above the ground (seed 6.1, known-height cue).

Per keyframe: fit the ground plane to map points below the horizon (camera frame), read the
camera height in map units ``h_k``, and the scale ``s_k = H / h_k``. The per-keyframe values are
the scale-drift record; a running median over keyframes smooths them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from amrvio.geometry.ground_plane import PlaneStatus, fit_ground_plane
from amrvio.geometry.projection import MIN_DEPTH
from amrvio.types.lie import transform_points

F64 = NDArray[np.float64]
NEAR_DEPTH = 8.0


@dataclass(frozen=True, slots=True)
class HeightEstimate:
    """One keyframe's ground-plane reading: ``height_map`` in map units, ``scale = H / h``."""

    frame_index: int
    status: PlaneStatus
    height_map: float
    scale: float
    n_inliers: int


def estimate_height(
    frame_index: int, points_cam: F64, camera_height_m: float, *, down_cam: F64 | None = None,
    seed: int = 0,
    max_depth_heights: float = NEAR_DEPTH,
) -> HeightEstimate:
    """Ground-plane RANSAC on (N, 3) camera-frame points of one keyframe.

    A second fit keeps only points nearer than ``max_depth_heights`` camera heights: far
    points have large depth errors, biased long (inverse-depth noise), which lifts the plane.
    """
    res = fit_ground_plane(points_cam, down_cam=down_cam, seed=seed, min_inliers=12)
    if not res.ok or res.height <= 0:
        return HeightEstimate(frame_index, res.status, float("nan"), float("nan"), 0)
    near = points_cam[:, 2] < max_depth_heights * res.height
    if int(near.sum()) >= 12:
        res2 = fit_ground_plane(points_cam[near], down_cam=down_cam, seed=seed, min_inliers=12)
        if res2.ok and res2.height > 0:
            res = res2
    return HeightEstimate(frame_index, res.status, res.height, camera_height_m / res.height,
                          int(res.inliers.sum()))


def height_at_keyframe(frame_index: int, T_cam_world: F64, points_world: F64,
                       camera_height_m: float, *, segment_scale: float = 1.0,
                       seed: int = 0) -> HeightEstimate:
    """The reading of one keyframe (pose 4x4 ``T_cam_world``) from the (N, 3) map points it
    sees, in global units: a map segment whose unit is ``segment_scale`` global units."""
    Pc = transform_points(T_cam_world, points_world)
    Pc = Pc[Pc[:, 2] > MIN_DEPTH]
    est = estimate_height(frame_index, Pc, camera_height_m, seed=seed)
    if np.isfinite(est.scale):
        est = HeightEstimate(est.frame_index, est.status, est.height_map * segment_scale,
                             est.scale / segment_scale, est.n_inliers)
    return est


def smooth_scales(estimates: list[HeightEstimate], n_frames: int, half_window: int = 5) -> F64:
    """Per-frame scale (n_frames,): running median of the valid keyframe scales over
    ``2*half_window+1`` keyframes, linearly interpolated between keyframes, held at the ends.
    Returns ones when no keyframe has a valid estimate."""
    valid = [e for e in estimates if np.isfinite(e.scale)]
    if not valid:
        return np.ones(n_frames)
    idx = np.array([e.frame_index for e in valid], dtype=float)
    s = np.array([e.scale for e in valid])
    sm = np.array([np.median(s[max(0, i - half_window): i + half_window + 1])
                   for i in range(len(s))])
    return np.asarray(np.interp(np.arange(n_frames, dtype=float), idx, sm), dtype=np.float64)


__all__ = ["HeightEstimate", "estimate_height", "height_at_keyframe", "smooth_scales"]
