"""Two-view initialisation with model selection: homography or essential matrix.

Both models are fitted by RANSAC on the same matches and scored on them (truncated chi-square
scores of the symmetric transfer and epipolar errors, as in ORB-SLAM); the homography is chosen
when it explains the matches as well as the essential matrix does (a planar scene, or little
translation), and is then decomposed (Faugeras/Malis) into at most four motions, among which
cheirality and reprojection choose. The motion is accepted on the quality of its triangulated
points: how many are in front of both views with a small reprojection error, and how large the
parallax of the best ``min_triangulated`` of them is (the ``min_triangulated``-th largest).

A camera that only rotates is recognised first (Wahba's problem on the bearings); its rotation
is returned with the failure, so that the caller can keep tracking it. Failure is data:
``TwoViewResult.status`` says why (too few points or inliers, low parallax, pure rotation,
ambiguous homography, too few points triangulated).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

import cv2
import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ShapeError
from amrvio.geometry.checks import F64, check_matrix, check_points
from amrvio.geometry.projection import normalized_to_bearings, pixels_to_normalized
from amrvio.geometry.triangulation import TriangulationResult, triangulate
from amrvio.types.lie import se3_matrix

B = NDArray[np.bool_]
_CHI2_1DOF = 3.841  # 95 % of chi-square with 1 dof (point to epipolar line)
_CHI2_2DOF = 5.991  # 95 % with 2 dof (point to point), also the score's cap (ORB-SLAM)


class TwoViewStatus(Enum):
    """Outcome of a two-view initialisation attempt."""

    OK = "ok"
    TOO_FEW_POINTS = "too_few_points"
    TOO_FEW_INLIERS = "too_few_inliers"
    LOW_PARALLAX = "low_parallax"
    PURE_ROTATION = "pure_rotation"
    AMBIGUOUS = "ambiguous"
    TOO_FEW_POINTS_TRIANGULATED = "too_few_points_triangulated"


class TwoViewModel(Enum):
    """Which model gave the motion."""

    NONE = "none"
    ROTATION = "rotation"
    HOMOGRAPHY = "homography"
    ESSENTIAL = "essential"


@dataclass(frozen=True, slots=True)
class TwoViewResult:
    """Relative pose of view 2 w.r.t. view 1 and the triangulated points.

    ``T_c2_c1``: 4x4, translation of unit norm (scale is unobservable); for PURE_ROTATION and
    LOW_PARALLAX the best rotation with zero translation. ``inliers``: (N,) bool inliers of the
    chosen model. ``points_c1``: (N, 3) points in camera-1 frame (valid where ``point_valid``).
    ``median_parallax_deg``: rotation-compensated ray angle of the inliers; ``parallax_deg``:
    the ``min_triangulated``-th largest parallax of the valid points (the gate);
    ``homography_ratio``: S_H / (S_H + S_F).
    """

    status: TwoViewStatus
    T_c2_c1: F64
    inliers: B
    points_c1: F64
    point_valid: B
    median_parallax_deg: float
    median_flow_px: float
    model: TwoViewModel = TwoViewModel.NONE
    parallax_deg: float = 0.0
    homography_ratio: float = float("nan")

    @property
    def ok(self) -> bool:
        return self.status is TwoViewStatus.OK


@dataclass(frozen=True, slots=True)
class TwoViewConfig:
    """Gates of the two-view initialiser (angles in degrees, distances in pixels).

    ``min_parallax_deg``: the ``min_triangulated``-th largest parallax of the triangulated points
    must reach it (a camera whose rays one rotation explains to within ``max_reproj_px``, even
    the ``min_triangulated`` worst, is called rotating and fails first);
    ``min_point_parallax_deg``: parallax a point needs to count;
    ``homography_ratio``: S_H / (S_H + S_F) above which the homography is used;
    ``min_good_ratio``: share of the model's inliers that must agree with the chosen motion
    (in front of both views with a small reprojection error, or too far to tell).
    """

    min_points: int = 50
    min_inliers: int = 40
    min_flow_px: float = 8.0
    min_parallax_deg: float = 1.0
    min_point_parallax_deg: float = 0.5
    ransac_thresh_px: float = 1.0
    max_reproj_px: float = 2.0
    min_triangulated: int = 50
    homography_ratio: float = 0.45
    min_good_ratio: float = 0.6
    seed: int = 0


def _rotation_parallax_deg(b1: F64, b2: F64, R_2_1: F64) -> F64:
    """(N,) angle between b2 and the rotated b1: parallax left after removing rotation."""
    c = np.sum(b2 * (b1 @ R_2_1.T), axis=1)
    return np.asarray(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))), dtype=np.float64)


def best_rotation(b1: F64, b2: F64) -> F64:
    """Rotation R minimising sum |b2 - R b1|^2 (Kabsch/Wahba, closed form via SVD)."""
    H = b1.T @ b2
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(Vt.T @ U.T))
    D = np.diag([1.0, 1.0, d])
    R: F64 = Vt.T @ D @ U.T
    return R


def robust_rotation(b1: F64, b2: F64, iterations: int = 3) -> tuple[F64, F64]:
    """Best rotation b2 ~ R b1 with the worst rays re-weighted out (three passes that keep the
    rays within 3x the median residual); returns R and the (N,) residual angles in degrees."""
    keep = np.ones(len(b1), dtype=bool)
    R = best_rotation(b1, b2)
    for _ in range(iterations):
        res = _rotation_parallax_deg(b1, b2, R)
        keep = res <= max(3.0 * float(np.median(res)), 1e-6)
        if int(keep.sum()) < 3:
            break
        R = best_rotation(b1[keep], b2[keep])
    return R, _rotation_parallax_deg(b1, b2, R)


def order_stat_desc(values: F64, k: int) -> float:
    """The ``k``-th largest value (1-based; the smallest when there are fewer than k)."""
    if len(values) == 0:
        return 0.0
    idx = max(len(values) - k, 0)
    return float(np.partition(values, idx)[idx])


def _skew(v: F64) -> F64:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _score_homography(H: F64, x1: F64, x2: F64, inv_sigma2: float) -> tuple[float, B]:
    """Truncated symmetric-transfer score of H (normalized coordinates) and its inliers."""
    def transfer(M: F64, a: F64, b: F64) -> F64:
        p = np.c_[a, np.ones(len(a))] @ M.T
        w = np.where(np.abs(p[:, 2]) > 1e-12, p[:, 2], 1e-12)
        return np.asarray(np.sum((p[:, :2] / w[:, None] - b) ** 2, axis=1) * inv_sigma2)

    e12 = transfer(H, x1, x2)
    e21 = transfer(np.asarray(np.linalg.inv(H), dtype=np.float64), x2, x1)
    inl = (e12 < _CHI2_2DOF) & (e21 < _CHI2_2DOF)
    score = np.where(e12 < _CHI2_2DOF, _CHI2_2DOF - e12, 0.0) + \
        np.where(e21 < _CHI2_2DOF, _CHI2_2DOF - e21, 0.0)
    return float(np.sum(score[inl])), inl


def _score_essential(E: F64, x1: F64, x2: F64, inv_sigma2: float) -> tuple[float, B]:
    """Truncated score of the point-to-epipolar-line distances in both views."""
    h1 = np.c_[x1, np.ones(len(x1))]
    h2 = np.c_[x2, np.ones(len(x2))]
    l2 = h1 @ E.T  # lines in view 2
    l1 = h2 @ E  # lines in view 1
    num = np.sum(h2 * l2, axis=1) ** 2
    d2 = num / (l2[:, 0] ** 2 + l2[:, 1] ** 2 + 1e-300) * inv_sigma2
    d1 = num / (l1[:, 0] ** 2 + l1[:, 1] ** 2 + 1e-300) * inv_sigma2
    inl = (d1 < _CHI2_1DOF) & (d2 < _CHI2_1DOF)
    score = np.where(d1 < _CHI2_1DOF, _CHI2_2DOF - d1, 0.0) + \
        np.where(d2 < _CHI2_1DOF, _CHI2_2DOF - d2, 0.0)
    return float(np.sum(score[inl])), inl


@dataclass(frozen=True, slots=True)
class _Candidate:
    """One motion hypothesis: points ``good`` (inliers in front, small reprojection, enough
    parallax), ``n_consistent``: inliers whose rays agree with it, and ``n_support``: all matches
    that agree with it (in front of both views with a small reprojection error, or too little
    parallax to tell: a far point noisy enough to land behind must not decide)."""

    T21: F64
    tri: TriangulationResult
    good: B
    n_good: int
    n_consistent: int
    n_support: int


def _check_motion(R: F64, t: F64, x1: F64, x2: F64, inl: B, cfg: TwoViewConfig,
                  focal: float) -> _Candidate:
    t = t.ravel() / (np.linalg.norm(t) + 1e-300)
    T21 = se3_matrix(R, t)
    tri = triangulate(np.eye(4), T21, x1, x2, min_parallax_deg=cfg.min_point_parallax_deg,
                      max_reproj_px=cfg.max_reproj_px, focal_px=focal)
    good = tri.valid & inl
    low = tri.parallax_deg < cfg.min_point_parallax_deg
    small = tri.reproj_err <= cfg.max_reproj_px
    consistent = inl & ((tri.in_front & small) | low)
    support = (tri.in_front & small) | low
    return _Candidate(T21, tri, good, int(good.sum()), int(consistent.sum()), int(support.sum()))


def essential_ransac(x1: F64, x2: F64, thresh_px: float, focal: float) -> tuple[F64, B] | None:
    """The essential matrix of (N, 2) normalised pairs by OpenCV's five-point RANSAC (threshold
    ``thresh_px`` at ``focal`` pixels) and its inlier mask; None when it finds none. Seed
    OpenCV's RNG (``cv2.setRNGSeed``) first for a repeatable result."""
    E, mask = cv2.findEssentialMat(x1, x2, np.eye(3), method=cv2.RANSAC, prob=0.999,
                                   threshold=thresh_px / focal)
    if E is None or E.shape != (3, 3):
        return None
    return np.asarray(E, dtype=np.float64), mask.ravel().astype(bool)


def two_view_init(
    pts1_px: F64, pts2_px: F64, K: F64, config: TwoViewConfig | None = None
) -> TwoViewResult:
    """Relative pose and structure from (N, 2) pixel matches of two views with pinhole ``K``."""
    cfg = config or TwoViewConfig()
    p1 = check_points("pts1_px", pts1_px, 2)
    p2 = check_points("pts2_px", pts2_px, 2)
    Km = check_matrix("K", K, (3, 3))
    if len(p1) != len(p2):
        raise ShapeError(f"pts1_px and pts2_px differ in length: {len(p1)} vs {len(p2)}")
    n = len(p1)
    empty = np.zeros(n, dtype=bool)
    flow = float(np.median(np.linalg.norm(p2 - p1, axis=1))) if n else 0.0

    def fail(status: TwoViewStatus, par: float = 0.0, inl: B | None = None,
             T21: F64 | None = None, model: TwoViewModel = TwoViewModel.NONE,
             kth: float = 0.0, ratio: float = float("nan")) -> TwoViewResult:
        return TwoViewResult(status, np.eye(4) if T21 is None else T21,
                             empty if inl is None else inl, np.zeros((n, 3)), empty, par, flow,
                             model, kth, ratio)

    if n < cfg.min_points:
        return fail(TwoViewStatus.TOO_FEW_POINTS)
    x1 = pixels_to_normalized(p1, Km)
    x2 = pixels_to_normalized(p2, Km)
    b1 = normalized_to_bearings(x1)
    b2 = normalized_to_bearings(x2)
    focal = 0.5 * (Km[0, 0] + Km[1, 1])
    # a camera that only rotates: one rotation explains the rays to within the reprojection
    # gate, even the min_triangulated worst of them (a sideways translation is NOT explained
    # this well unless the scene is far, so it goes on to the models)
    R_rot, rot_res = robust_rotation(b1, b2)
    rot_kth = order_stat_desc(rot_res, cfg.min_triangulated)
    rot_med = float(np.median(rot_res))
    T_rot = se3_matrix(R_rot, np.zeros(3))
    if np.radians(rot_kth) * focal < cfg.max_reproj_px:
        status = (TwoViewStatus.LOW_PARALLAX if flow < cfg.min_flow_px
                  else TwoViewStatus.PURE_ROTATION)
        return fail(status, rot_med, T21=T_rot, model=TwoViewModel.ROTATION, kth=rot_kth)
    inv_sigma2 = focal * focal  # one pixel of noise, in normalized units
    cv2.setRNGSeed(cfg.seed)
    ess = essential_ransac(x1, x2, cfg.ransac_thresh_px, focal)
    H, _ = cv2.findHomography(x1, x2, cv2.RANSAC, 2.0 * cfg.ransac_thresh_px / focal)
    s_e, inl_e = _score_essential(ess[0], x1, x2, inv_sigma2) if ess else (0.0, empty)
    s_h, inl_h = (_score_homography(np.asarray(H, dtype=np.float64), x1, x2, inv_sigma2)
                  if H is not None and abs(np.linalg.det(H)) > 1e-12 else (0.0, empty))
    ratio = s_h / (s_h + s_e) if s_h + s_e > 0 else float("nan")
    use_h = bool(s_h > 0 and ratio > cfg.homography_ratio)
    model = TwoViewModel.HOMOGRAPHY if use_h else TwoViewModel.ESSENTIAL
    inl = inl_h if use_h else (ess[1] & inl_e if ess else empty)
    if int(inl.sum()) < cfg.min_inliers:
        return fail(TwoViewStatus.TOO_FEW_INLIERS, rot_med, inl, T_rot, model, rot_kth, ratio)
    cands: list[_Candidate] = []
    if use_h and H is not None:
        _, Rs, ts, _ = cv2.decomposeHomographyMat(np.asarray(H, dtype=np.float64), np.eye(3))
        cands = [_check_motion(R, t, x1, x2, inl, cfg, focal) for R, t in zip(Rs, ts, strict=True)
                 if np.linalg.norm(t) > 1e-9]
    elif ess is not None:
        R1, R2, t = cv2.decomposeEssentialMat(ess[0])
        cands = [_check_motion(R, s * t, x1, x2, inl, cfg, focal)
                 for R in (R1, R2) for s in (1.0, -1.0)]
    if not cands:
        return fail(TwoViewStatus.TOO_FEW_INLIERS, rot_med, inl, T_rot, model, rot_kth, ratio)
    # the matches off the model (off the plane, for a homography) decide between motions that
    # explain the model's inliers equally well (the two-fold ambiguity of a homography)
    cands.sort(key=lambda c: (c.n_support, c.n_good), reverse=True)
    best = cands[0]
    par_in = float(np.median(_rotation_parallax_deg(b1[inl], b2[inl], best.T21[:3, :3])))
    kth = order_stat_desc(best.tri.parallax_deg[best.good], cfg.min_triangulated)
    if len(cands) > 1 and cands[1].n_support > best.n_support - max(10.0, 0.03 * n):
        return fail(TwoViewStatus.AMBIGUOUS, par_in, inl, best.T21, model, kth, ratio)
    if best.n_good < cfg.min_triangulated or \
            best.n_consistent < cfg.min_good_ratio * int(inl.sum()):
        return TwoViewResult(TwoViewStatus.TOO_FEW_POINTS_TRIANGULATED, best.T21, inl,
                             best.tri.points_world, best.good, par_in, flow, model, kth, ratio)
    if kth < cfg.min_parallax_deg:
        return fail(TwoViewStatus.LOW_PARALLAX, par_in, inl, best.T21, model, kth, ratio)
    return TwoViewResult(TwoViewStatus.OK, best.T21, inl, best.tri.points_world, best.good,
                         par_in, flow, model, kth, ratio)


__all__ = ["TwoViewConfig", "TwoViewModel", "TwoViewResult", "TwoViewStatus", "best_rotation",
           "essential_ransac", "order_stat_desc", "robust_rotation", "two_view_init"]
