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


# ---- the parallax reference frame (not the VO's keyframes: see frontend.keyframe_policy) -------

@dataclass(frozen=True, slots=True)
class ParallaxReferenceConfig:
    """When the diagnostics renew the frame parallax is measured against, and flag low parallax.

    A new reference starts when fewer than ``min_tracks`` tracks survive, fewer than
    ``min_track_frac`` of the reference's own, or the parallax exceeds ``max_parallax_px``.
    Parallax below ``low_parallax_px``, at least ``min_frames_low_parallax`` frames after the
    reference, is flagged as low.
    """

    min_tracks: int = 40
    min_track_frac: float = 0.5
    max_parallax_px: float = 30.0
    low_parallax_px: float = 5.0
    min_frames_low_parallax: int = 10


def parallax_reference_due(
    n_tracked: int, n_reference: int, parallax_px: float, config: ParallaxReferenceConfig
) -> bool:
    """True when the parallax reference should be renewed (see :class:`ParallaxReferenceConfig`):
    ``n_tracked`` tracks survive of the reference's ``n_reference``; NaN parallax never renews."""
    return bool(
        n_tracked < config.min_tracks
        or n_tracked < config.min_track_frac * n_reference
        or (np.isfinite(parallax_px) and parallax_px > config.max_parallax_px)
    )


def low_parallax(frames_since_reference: int, parallax_px: float,
                 config: ParallaxReferenceConfig) -> bool:
    """Low-parallax flag: parallax below ``low_parallax_px`` after enough frames."""
    return bool(
        frames_since_reference >= config.min_frames_low_parallax
        and np.isfinite(parallax_px)
        and parallax_px < config.low_parallax_px
    )


class ParallaxReference:
    """The reference frame's tracks: ``pts_ref`` (N, 2) float32 where they were detected,
    ``pts`` (N, 2) float32 where they are now, ``n_detected`` at the reference,
    ``R_ref_cur`` the gyro rotation since the reference (valid while ``gyro_ok``) and
    ``frames_since`` the reference. Changed only by :meth:`restart`, :meth:`rotate` and
    :meth:`advance`."""

    def __init__(self) -> None:
        self.restart(np.zeros((0, 2), np.float32))

    def restart(self, pts: NDArray[np.float32]) -> None:
        """Make the current frame the reference, with (N, 2) detected ``pts``."""
        self.pts = pts
        self.pts_ref = pts.copy()
        self.n_detected = int(pts.shape[0])
        self.R_ref_cur = np.eye(3)
        self.gyro_ok = True
        self.frames_since = 0

    def rotate(self, R_prev_cur: F64 | None) -> None:
        """Accumulate the gyro rotation prev -> cur; None (no gyro) invalidates it."""
        if R_prev_cur is None:
            self.gyro_ok = False
        else:
            self.R_ref_cur = self.R_ref_cur @ R_prev_cur

    def advance(self, pts_cur: NDArray[np.float32], ok: NDArray[np.bool_]) -> None:
        """Keep the tracks with ``ok`` (N,), now at ``pts_cur`` (N, 2), and count the frame."""
        self.pts, self.pts_ref = pts_cur[ok], self.pts_ref[ok]
        self.frames_since += 1

    def measure(self, camera: CameraModel) -> ParallaxResult:
        """Rotation-compensated parallax of the surviving tracks since the reference."""
        R_cur_ref = self.R_ref_cur.T if self.gyro_ok else None
        return rotation_compensated_parallax(camera, self.pts_ref, self.pts, R_cur_ref)
