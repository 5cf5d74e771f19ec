"""Rotation-compensated parallax of tracked features against a keyframe (seed section 2).

Rotation alone moves features but gives no depth: only the flow left after removing it
(translation-induced parallax) makes triangulation and monocular initialisation possible. A
feature seen along ray d_kf in the keyframe would, under a pure rotation ``R_cur_kf``, appear at
``project(R_cur_kf d_kf)``; the parallax is its distance to where it is actually tracked. The
rotation comes from the gyro when available, else from the essential matrix (cv2, RANSAC).
Forward motion in a corridor is the classic low-parallax case: features near the focus of
expansion barely move.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ShapeError
from amrvio.types.camera import CameraModel

F64 = NDArray[np.float64]


class RotationSource(enum.Enum):
    GYRO = "gyro"
    ESSENTIAL = "essential"
    NONE = "none"


@dataclass(frozen=True, slots=True)
class ParallaxResult:
    """``median_px``: median rotation-compensated parallax (NaN with < 5 tracks); ``n_tracks``;
    ``rotation_source``; ``R_cur_kf``: the rotation used (identity when none)."""

    median_px: float
    n_tracks: int
    rotation_source: RotationSource
    R_cur_kf: F64


def _check_pts(pts: NDArray[np.floating], name: str) -> F64:
    p = np.asarray(pts, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2:
        raise ShapeError(f"{name} must be (N,2) pixel coordinates, got {p.shape}")
    if not np.all(np.isfinite(p)):
        raise ShapeError(f"{name} contains non-finite values")
    return p


def rotation_from_essential(
    camera: CameraModel, pts_kf: F64, pts_cur: F64, threshold_px: float = 1.0
) -> F64 | None:
    """``R_cur_kf`` from the essential matrix of (N, 2) correspondences, or None (< 8 points or
    failure). Points are undistorted first; the RANSAC threshold is in pixels of ``camera.fx``."""
    if pts_kf.shape[0] < 8:
        return None
    rk, rc = camera.unproject(pts_kf), camera.unproject(pts_cur)
    ok = np.all(np.isfinite(rk), axis=1) & np.all(np.isfinite(rc), axis=1)
    if int(ok.sum()) < 8:
        return None
    xk, xc = rk[ok, :2], rc[ok, :2]
    thr = threshold_px / camera.fx
    E, inl = cv2.findEssentialMat(xk, xc, np.eye(3), method=cv2.RANSAC, prob=0.999, threshold=thr)
    if E is None or E.shape != (3, 3):
        return None
    n, R, _t, _m = cv2.recoverPose(E, xk, xc, np.eye(3), mask=inl)
    if n < 5:
        return None
    return np.asarray(R, dtype=np.float64)


def rotation_compensated_parallax(
    camera: CameraModel,
    pts_kf: NDArray[np.floating],
    pts_cur: NDArray[np.floating],
    R_cur_kf: F64 | None = None,
    use_essential: bool = True,
) -> ParallaxResult:
    """Median distance (px) between tracked ``pts_cur`` and the rotation-only prediction of
    ``pts_kf`` (both (N, 2) pixels). ``R_cur_kf`` (3, 3) maps keyframe-camera directions into the
    current camera (from the gyro); without it the essential matrix is used when
    ``use_essential``, else no compensation (raw median flow)."""
    pk, pc = _check_pts(pts_kf, "pts_kf"), _check_pts(pts_cur, "pts_cur")
    if pk.shape != pc.shape:
        raise ShapeError(f"pts_kf {pk.shape} and pts_cur {pc.shape} differ")
    source = RotationSource.GYRO
    R = None if R_cur_kf is None else np.asarray(R_cur_kf, dtype=np.float64)
    if R is not None and R.shape != (3, 3):
        raise ShapeError(f"R_cur_kf must be (3,3), got {R.shape}")
    if R is None and use_essential:
        R = rotation_from_essential(camera, pk, pc)
        source = RotationSource.ESSENTIAL
    if R is None:
        R = np.eye(3)
        source = RotationSource.NONE
    if pk.shape[0] < 5:
        return ParallaxResult(float("nan"), int(pk.shape[0]), source, R)
    rays = camera.unproject(pk)
    ok = np.all(np.isfinite(rays), axis=1)
    rot = rays[ok] @ R.T
    front = rot[:, 2] > 1e-9
    pred = camera.project(rot[front])
    d = np.linalg.norm(pred - pc[ok][front], axis=1)
    d = d[np.isfinite(d)]
    med = float(np.median(d)) if d.size >= 5 else float("nan")
    if source is RotationSource.ESSENTIAL:
        # A wrong essential-matrix rotation (noisy tracks, near-degenerate motion) can only make
        # the compensated flow larger than no compensation at all: keep the smaller.
        raw = float(np.median(np.linalg.norm(pc - pk, axis=1)))
        if not np.isfinite(med) or raw < med:
            return ParallaxResult(raw, int(pk.shape[0]), RotationSource.NONE, np.eye(3))
    return ParallaxResult(med, int(pk.shape[0]), source, R)
