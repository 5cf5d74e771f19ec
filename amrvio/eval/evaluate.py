"""One call that evaluates an estimated trajectory against ground truth: :func:`evaluate`.

Steps: associate by timestamp -> align (none, origin, SE3 or Sim3 Umeyama, optionally on the first
N poses) -> ATE and RPE on the aligned estimate -> the Sim3 scale and its error -> the Sim3 scale of
consecutive windows (scale drift). The figures equal evo's ``evo_ape`` / ``evo_rpe`` with the same
alignment (``-a``, ``-as``, ``--align_origin``, ``--n_to_align``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import EvaluationError, ShapeError
from amrvio.eval.associate import associate
from amrvio.eval.metrics import (
    AlignMethod,
    DeltaUnit,
    ErrorStats,
    RpeResult,
    ScaleWindow,
    WindowStatus,
    align_trajectory,
    ate_errors_m,
    rpe,
    scale_windows,
)
from amrvio.geometry.align import umeyama
from amrvio.types.lie import Sim3
from amrvio.types.trajectory import Trajectory

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


def _finite_or_none(x: float | None) -> float | None:
    if x is None or not math.isfinite(x):
        return None
    return float(x)


@dataclass(frozen=True, slots=True, eq=False)
class EvalResult:
    """Everything :func:`evaluate` measured. ``to_json_dict()`` gives the flat summary."""

    align: AlignMethod
    n_align: int | None
    max_diff_s: float
    est_poses: int
    gt_poses: int
    matched_poses: int
    idx_est: I64
    idx_gt: I64
    alignment: Sim3  # applied to the estimate: est_aligned = est.transformed(alignment)
    est_aligned: Trajectory  # associated, aligned estimate
    gt_matched: Trajectory  # associated ground truth
    scale: float | None  # Sim3 (Umeyama) scale estimate -> gt, whatever the alignment
    path_length_m: float  # ground-truth path length over the associated poses
    ate_errors_m: F64
    ate: ErrorStats
    rpe_delta: float
    rpe_delta_unit: DeltaUnit
    rpe_all_pairs: bool
    rpe: RpeResult
    drift_windows: tuple[ScaleWindow, ...]

    @property
    def scale_error_pct(self) -> float | None:
        """``|1 - s| * 100`` with s the Sim3 scale."""
        return None if self.scale is None else abs(1.0 - self.scale) * 100.0

    @property
    def scale_drift_pct(self) -> float | None:
        """``(max / min - 1) * 100`` over the window scales; None with fewer than 2 windows."""
        s = [w.scale for w in self.drift_windows if w.scale is not None]
        if len(s) < 2:
            return None
        return (max(s) / min(s) - 1.0) * 100.0

    def to_json_dict(self) -> dict[str, Any]:
        """Summary for ``--json``: flat keys with units, then the detailed statistics."""
        return {
            "align": self.align.value,
            "n_align": self.n_align,
            "max_diff_s": self.max_diff_s,
            "est_poses": self.est_poses,
            "gt_poses": self.gt_poses,
            "matched_poses": self.matched_poses,
            "path_length_m": self.path_length_m,
            "ate_rmse_m": _finite_or_none(self.ate.rmse),
            "ate_mean_m": _finite_or_none(self.ate.mean),
            "ate_median_m": _finite_or_none(self.ate.median),
            "ate_std_m": _finite_or_none(self.ate.std),
            "ate_min_m": _finite_or_none(self.ate.min),
            "ate_max_m": _finite_or_none(self.ate.max),
            "scale": self.scale,
            "scale_error_pct": self.scale_error_pct,
            "rpe_delta": self.rpe_delta,
            "rpe_delta_unit": self.rpe_delta_unit.value,
            "rpe_all_pairs": self.rpe_all_pairs,
            "rpe_pairs": int(self.rpe.pairs.shape[0]),
            "rpe_trans_rmse_m": _finite_or_none(self.rpe.trans.rmse),
            "rpe_trans_mean_m": _finite_or_none(self.rpe.trans.mean),
            "rpe_trans_max_m": _finite_or_none(self.rpe.trans.max),
            "rpe_rot_rmse_deg": _finite_or_none(self.rpe.rot_deg.rmse),
            "rpe_rot_mean_deg": _finite_or_none(self.rpe.rot_deg.mean),
            "rpe_rot_max_deg": _finite_or_none(self.rpe.rot_deg.max),
            "scale_drift_pct": self.scale_drift_pct,
            "scale_drift_windows": [w.to_dict() for w in self.drift_windows],
            "alignment_sim3": self.alignment.matrix().tolist(),
            "ate_stats_m": self.ate.to_dict(),
            "rpe_trans_stats_m": self.rpe.trans.to_dict(),
            "rpe_rot_stats_deg": self.rpe.rot_deg.to_dict(),
        }


def evaluate(
    est: Trajectory,
    gt: Trajectory,
    align: AlignMethod | str = AlignMethod.SIM3,
    delta: float = 1.0,
    delta_unit: DeltaUnit | str = DeltaUnit.FRAMES,
    max_diff_s: float = 0.01,
    n_align: int | None = None,
    drift_window_m: float | None = None,
    drift_window_frames: int | None = None,
    all_pairs: bool = False,
) -> EvalResult:
    """Compare ``est`` with ``gt`` (see the module docstring).

    est may have fewer (or more) poses than gt; only the associated ones count. RPE pairs are taken
    on the aligned estimate every ``delta`` frames or metres (evo's consecutive pairs, or every pair
    with ``all_pairs``). Drift windows: ``drift_window_frames`` poses or ``drift_window_m`` metres of
    ground-truth path (default 10 % of it).

    Raises:
        EvaluationError: no stamps match within ``max_diff_s``, or the alignment is undefined
            (for example fewer than 3 associated poses for se3 / sim3).
    """
    method = AlignMethod(align)
    unit = DeltaUnit(delta_unit)
    if n_align is not None and n_align < 1:
        raise EvaluationError(f"n_align must be >= 1, got {n_align}")
    idx_est, idx_gt = associate(est, gt, max_diff_s)
    if idx_est.size == 0:
        raise EvaluationError(
            f"no timestamps match within {max_diff_s} s (estimate {_span(est)}, ground truth "
            f"{_span(gt)}); check that both use the same clock and unit (KITTI poses without a times "
            "file are stamped 0, 1, 2, ...), or raise --max-diff"
        )
    est_m = _select_allow_repeats(est, idx_est)
    gt_m = _select_allow_repeats(gt, idx_gt)
    try:
        S_gtworld_estworld = align_trajectory(est_m, gt_m, method, n_align)
    except ShapeError as err:
        raise EvaluationError(
            f"cannot align with {method.value} on "
            f"{len(est_m) if n_align is None else min(n_align, len(est_m))} associated poses: {err}"
        ) from None
    est_a = est_m.transformed(S_gtworld_estworld)
    scale: float | None
    if method is AlignMethod.SIM3:
        scale = S_gtworld_estworld.s
    else:
        n = len(est_m) if n_align is None else min(n_align, len(est_m))
        try:
            scale = umeyama(est_m.positions_m[:n], gt_m.positions_m[:n], with_scale=True).s
        except ShapeError:
            scale = None
    errors = ate_errors_m(est_a, gt_m)
    try:
        rp = rpe(est_a, gt_m, delta, unit, all_pairs=all_pairs)
    except ShapeError as err:
        raise EvaluationError(f"RPE: {err}") from None
    try:
        windows = scale_windows(est_m, gt_m, drift_window_m, drift_window_frames)
    except ShapeError as err:
        raise EvaluationError(f"scale drift: {err}") from None
    return EvalResult(
        align=method,
        n_align=n_align,
        max_diff_s=float(max_diff_s),
        est_poses=len(est),
        gt_poses=len(gt),
        matched_poses=len(est_m),
        idx_est=idx_est,
        idx_gt=idx_gt,
        alignment=S_gtworld_estworld,
        est_aligned=est_a,
        gt_matched=gt_m,
        scale=scale,
        path_length_m=gt_m.path_length_m(),
        ate_errors_m=errors,
        ate=ErrorStats.from_errors(errors),
        rpe_delta=float(delta),
        rpe_delta_unit=unit,
        rpe_all_pairs=all_pairs,
        rpe=rp,
        drift_windows=windows,
    )


def _span(t: Trajectory) -> str:
    if len(t) == 0:
        return "empty"
    return f"{len(t)} poses, {t.stamps_s[0]:.6f}..{t.stamps_s[-1]:.6f} s"


def _select_allow_repeats(t: Trajectory, idx: I64) -> Trajectory:
    """``t.select(idx)``; a repeated index (possible with a large max_diff, as in evo) keeps its
    pose but gets a stamp nudged by 1 ns so that stamps stay strictly increasing."""
    if idx.size < 2 or np.all(np.diff(idx) > 0):
        return t.select(idx)
    stamps = np.array(t.stamps_s[idx], dtype=np.float64)
    for k in range(1, stamps.size):
        if stamps[k] <= stamps[k - 1]:
            stamps[k] = np.nextafter(stamps[k - 1] + 1e-9, np.inf)
    return Trajectory(stamps, t.positions_m[idx], t.quats_wxyz[idx])


__all__ = ["EvalResult", "EvaluationError", "WindowStatus", "evaluate"]
