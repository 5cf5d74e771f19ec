"""Ground plane from triangulated points (RANSAC), and camera height above it (seed 6.1)."""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

import numpy as np

from amrvio.geometry.checks import F64, check_points


class PlaneStatus(Enum):
    """Outcome of a ground-plane fit."""

    OK = "ok"
    TOO_FEW_POINTS = "too_few_points"
    TOO_FEW_INLIERS = "too_few_inliers"
    NOT_LEVEL = "not_level"


@dataclass(frozen=True, slots=True)
class PlaneResult:
    """Plane n . X + d = 0 in the frame of the input points, with ``normal`` pointing to the
    camera side (``d > 0`` when the origin is above the plane). ``height`` = distance of the
    origin (the camera centre, for camera-frame points) to the plane."""

    status: PlaneStatus
    normal: F64
    d: float
    inliers: np.ndarray

    @property
    def ok(self) -> bool:
        return self.status is PlaneStatus.OK

    @property
    def height(self) -> float:
        return abs(self.d)


def fit_plane_lsq(points: F64) -> tuple[F64, float]:
    """Total-least-squares plane through (N, 3) points: (unit normal, d)."""
    c = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - c, full_matrices=False)
    n = vt[-1]
    return n, float(-n @ c)


def fit_ground_plane(
    points_cam: F64,
    *,
    down_cam: F64 | None = None,
    max_tilt_deg: float = 20.0,
    inlier_frac_thresh: float = 0.02,
    min_inliers: int = 15,
    iterations: int = 200,
    seed: int = 0,
) -> PlaneResult:
    """RANSAC plane over (N, 3) camera-frame points lying below the horizon.

    ``down_cam``: expected gravity-down direction in the camera frame (default +y, the
    KITTI/OpenCV camera looking forward). Only points with positive ``down`` component are used
    and the plane normal must be within ``max_tilt_deg`` of ``down``. The inlier threshold is
    ``inlier_frac_thresh`` times the median below-horizon distance, so it scales with the map.
    """
    P = check_points("points_cam", points_cam, 3)
    down = np.array([0.0, 1.0, 0.0]) if down_cam is None else np.asarray(down_cam, float)
    down = down / np.linalg.norm(down)
    n_all = len(P)
    none = np.zeros(n_all, dtype=bool)
    below = (P @ down) > 0
    idx = np.flatnonzero(below)
    if len(idx) < max(3, min_inliers):
        return PlaneResult(PlaneStatus.TOO_FEW_POINTS, down, 0.0, none)
    Q = P[idx]
    scale = float(np.median(Q @ down))
    thresh = inlier_frac_thresh * max(scale, 1e-9) * 5.0
    rng = np.random.default_rng(seed)
    cos_tilt = np.cos(np.radians(max_tilt_deg))
    best_n, best_d, best_cnt = down, 0.0, -1
    best_mask = np.zeros(len(Q), dtype=bool)
    for _ in range(iterations):
        s = rng.choice(len(Q), 3, replace=False)
        a, b, c = Q[s]
        n = np.cross(b - a, c - a)
        nn = np.linalg.norm(n)
        if nn < 1e-12:
            continue
        n = n / nn
        if n @ down < 0:
            n = -n
        if n @ down < cos_tilt:
            continue
        d = -float(n @ a)
        mask = np.abs(Q @ n + d) < thresh
        cnt = int(mask.sum())
        if cnt > best_cnt:
            best_n, best_d, best_cnt, best_mask = n, d, cnt, mask
    if best_cnt < min_inliers:
        return PlaneResult(PlaneStatus.TOO_FEW_INLIERS, down, 0.0, none)
    # least-squares polish on the inliers, twice
    n, d = best_n, best_d
    mask = best_mask
    for _ in range(2):
        n, d = fit_plane_lsq(Q[mask])
        if n @ down < 0:
            n, d = -n, -d
        mask = np.abs(Q @ n + d) < thresh
        if int(mask.sum()) < min_inliers:
            return PlaneResult(PlaneStatus.TOO_FEW_INLIERS, down, 0.0, none)
    inl = none.copy()
    inl[idx[mask]] = True
    # normal n points along "down"; flip so it points to the camera side (up)
    n_up, d_up = -n, -d
    if -n_up @ down < cos_tilt:
        return PlaneResult(PlaneStatus.NOT_LEVEL, n_up, d_up, inl)
    return PlaneResult(PlaneStatus.OK, n_up, d_up, inl)


__all__ = ["PlaneResult", "PlaneStatus", "fit_ground_plane", "fit_plane_lsq"]
