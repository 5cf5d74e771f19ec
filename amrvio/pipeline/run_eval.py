"""``eval.json``: a run against the dataset's ground truth, when it has one.

The reference is the camera's ground truth at the image times: the dataset's body poses
right-multiplied by ``T_body_cam`` (EuRoC, TUM-VI, the simulator), or its camera poses (KITTI),
interpolated at each image time inside the ground truth's span. The estimate is the refined
trajectory of the frames that have a pose (``trajectory.tum``). Sim3 alignment gives the ATE
whatever the scale; with a metric scale source (wheel odometry, ``scale.camera_height_m``) an
SE3 alignment also gives the metric ATE and the scale error (the Sim3 scale's distance from 1).
With VIO the estimate and the reference are body (IMU) poses, and the IMU makes the scale
metric: both alignments are reported.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amrvio.config import PipelineConfig
from amrvio.errors import EvaluationError, ShapeError
from amrvio.eval.evaluate import EvalResult, evaluate
from amrvio.io.base import Dataset
from amrvio.pipeline.pipeline import PipelineOutput
from amrvio.pipeline.records import PoseStatus
from amrvio.types.trajectory import Trajectory

F64 = NDArray[np.float64]

MIN_EXTENT_M = 0.01
"""A ground truth that spans less than this over the posed frames is not aligned (at rest)."""

MAX_DIFF_S = 1e-6
"""Estimate and reference share the image stamps; association needs no tolerance beyond rounding."""


@dataclass(frozen=True, slots=True, eq=False)
class RunEvaluation:
    """The figures of ``eval.json`` (``summary``) and the Sim3 result behind the report's top
    view (None when the evaluation failed; ``summary["error"]`` says why)."""

    summary: dict[str, Any]
    sim3: EvalResult | None
    se3: EvalResult | None


def camera_groundtruth(dataset: Dataset) -> tuple[Trajectory | None, str]:
    """The camera's ground-truth poses ``T_world_cam`` and how they were made; (None, why) when
    the dataset has none or it cannot be put in the camera frame."""
    gt = dataset.groundtruth
    if gt is None or len(gt) == 0:
        return None, "the dataset has no ground truth"
    if dataset.groundtruth_frame == "cam":
        return gt, "the dataset's camera poses"
    if dataset.T_body_cam is None:
        return None, ("the ground truth gives body poses and the calibration gives no camera-body "
                      "transform (T_body_cam)")
    return gt.right_multiplied(dataset.T_body_cam), "the dataset's body poses times T_body_cam"


def posed_indices(out: PipelineOutput) -> NDArray[np.int64]:
    """Positions of the records in ``trajectory.tum``: not LOST, with a finite refined pose."""
    keep = np.array([r.status is not PoseStatus.LOST for r in out.records], dtype=bool)
    if len(out.T_world_cam) != len(keep):  # tracking off: no pose at all
        return np.zeros(0, dtype=np.int64)
    finite = np.all(np.isfinite(out.T_world_cam.reshape(-1, 16)), axis=1)
    return np.flatnonzero(keep & finite).astype(np.int64)


def estimate_trajectory(out: PipelineOutput) -> Trajectory:
    """The poses of ``trajectory.tum``: the refined ``T_world_cam`` of the frames with a pose,
    or with VIO the body poses ``T_world_body``."""
    idx = posed_indices(out)
    if not idx.size:
        return Trajectory.from_matrices(np.zeros(0), np.zeros((0, 4, 4)))
    T = out.T_world_cam if out.body is None else out.body.T_world_body
    return Trajectory.from_matrices(out.stamps_ns[idx] * 1e-9, T[idx])


def yaw_alignment(est_m: F64, gt_m: F64) -> dict[str, float]:
    """Positions (N, 3) of a gravity-aligned estimate against the reference, aligned the way VIO
    is observable: a rotation about gravity (z) and a translation, with and without a scale
    (4 and 5 degrees of freedom; defined on a straight path too, where Umeyama's SE3/Sim3 are
    not). Returns ``ate_m`` (metric, no scale), ``ate_scaled_m``, ``scale`` (the reference per
    estimate unit) and ``scale_error_pct``."""
    e = est_m - est_m.mean(axis=0)
    g = gt_m - gt_m.mean(axis=0)
    H = e[:, :2].T @ g[:, :2]  # sum of e_xy g_xy^T
    yaw = float(np.arctan2(H[0, 1] - H[1, 0], H[0, 0] + H[1, 1]))
    c, sn = np.cos(yaw), np.sin(yaw)
    Re = e @ np.array([[c, -sn, 0.0], [sn, c, 0.0], [0.0, 0.0, 1.0]]).T
    scale = float(np.sum(g * Re) / max(float(np.sum(Re * Re)), 1e-300))
    ate = float(np.sqrt(np.mean(np.sum((g - Re) ** 2, axis=1))))
    ate_s = float(np.sqrt(np.mean(np.sum((g - scale * Re) ** 2, axis=1))))
    return {"ate_m": ate, "ate_scaled_m": ate_s, "scale": scale, "scale_error_pct": 100.0 * abs(scale - 1.0),
            "yaw_deg": float(np.degrees(yaw))}


def body_groundtruth(dataset: Dataset) -> tuple[Trajectory | None, str]:
    """The ground truth of the IMU body frame ``T_world_body`` and how it was made."""
    gt = dataset.groundtruth
    if gt is None or len(gt) == 0:
        return None, "the dataset has no ground truth"
    if dataset.groundtruth_frame == "body":
        return gt, "the dataset's body poses"
    if dataset.T_body_cam is None:
        return None, "the ground truth gives camera poses and the calibration no camera-body transform"
    return gt.right_multiplied(dataset.T_body_cam.inverse()), "the dataset's camera poses times T_cam_body"


def _brief(res: EvalResult) -> dict[str, Any]:
    d = res.to_json_dict()
    path = res.path_length_m
    d["ate_pct_of_path"] = 100.0 * res.ate.rmse / path if path > 0 else None
    return d


def evaluate_run(dataset: Dataset, out: PipelineOutput,
                 config: PipelineConfig | None = None) -> RunEvaluation | None:
    """The run against the ground truth (see the module docstring); None without ground truth
    of any kind. A failure (too few poses, a path without extent, no overlap in time) is an
    ``error`` in the summary, not an exception."""
    cfg = config or PipelineConfig()
    body = out.body is not None
    gt, source = body_groundtruth(dataset) if body else camera_groundtruth(dataset)
    n = len(out.records)
    if gt is None:
        if dataset.groundtruth is None:
            return None
        return RunEvaluation({"error": source, "n_frames": n}, None, None)
    est = estimate_trajectory(out)
    inside = (est.stamps_s >= gt.stamps_s[0]) & (est.stamps_s <= gt.stamps_s[-1])
    est = est.select(np.flatnonzero(inside))
    wheel = dataset.wheel is not None and cfg.scale.wheel.enabled
    metric = wheel or cfg.scale.camera_height_m is not None or body
    summary: dict[str, Any] = {
        "reference": f"{'body' if body else 'camera'} ground truth ({source}) interpolated at the image times",
        "n_frames": n, "n_in_trajectory": int(inside.size), "n_evaluated": len(est),
        "metric_scale_source": ("imu" if body else "wheel_odometry" if wheel
                                else "camera_height" if metric else None),
        "frame": "body" if body else "cam",
        "error": None, "sim3": None, "se3": None,
    }
    if len(est) == 0:
        summary["error"] = ("no frame has a pose (the run never initialised)" if not inside.size
                            else "no posed frame lies in the ground truth's time span")
        return RunEvaluation(summary, None, None)
    gt_at = gt.interpolated_at(est.stamps_s) if len(gt) >= 2 else gt
    extent = float(np.ptp(gt_at.positions_m, axis=0).max()) if len(gt_at) else 0.0
    if extent < MIN_EXTENT_M:
        summary["error"] = (f"the ground truth does not move over the posed frames (extent {extent:.4f} m): "
                            "nothing to align")
        return RunEvaluation(summary, None, None)
    if body and len(est) == len(gt_at) and len(est) >= 3:
        summary["yaw_aligned"] = yaw_alignment(est.positions_m, gt_at.positions_m)
    try:
        sim3 = evaluate(est, gt_at, align="sim3", max_diff_s=MAX_DIFF_S)
        se3 = evaluate(est, gt_at, align="se3", max_diff_s=MAX_DIFF_S) if metric else None
    except (EvaluationError, ShapeError) as err:
        summary["error"] = str(err)
        return RunEvaluation(summary, None, None)
    summary["sim3"] = _brief(sim3)
    summary["se3"] = _brief(se3) if se3 is not None else None
    summary["path_length_m"] = sim3.path_length_m
    summary["ate_sim3_m"] = sim3.ate.rmse
    summary["ate_sim3_pct_of_path"] = summary["sim3"]["ate_pct_of_path"]
    summary["scale_error_pct"] = sim3.scale_error_pct if metric else None
    summary["ate_metric_m"] = se3.ate.rmse if se3 is not None else None
    return RunEvaluation(summary, sim3, se3)


__all__ = ["MAX_DIFF_S", "MIN_EXTENT_M", "RunEvaluation", "camera_groundtruth", "estimate_trajectory",
           "body_groundtruth", "evaluate_run", "posed_indices",
           "yaw_alignment"]
