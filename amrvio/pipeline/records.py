"""The per-frame record: one :class:`FrameRecord` per frame, owned by the pipeline, carrying each
stage's report. It is the single source of ``health.csv``, the trajectory and the summary.

Poses are ``SE3`` values, ``T_world_cam`` (camera pose in the world). ``pose_online`` is the pose
known when the frame was processed (causal); ``pose_refined`` is the pose after the run, from the
bundle-adjusted keyframes (None for a frame that never got one).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import Enum

import numpy as np
from numpy.typing import NDArray

from amrvio.diagnostics.blur import BlurResult
from amrvio.diagnostics.frame import FrameHealth
from amrvio.estimator.camera_height import HeightEstimate
from amrvio.estimator.initializer import InitResult
from amrvio.estimator.local_mapping import KeyframeReport
from amrvio.estimator.wheel_calibration import WheelCalibration
from amrvio.frontend.tracking_types import TrackingReport
from amrvio.pipeline.vio_report import VioReport
from amrvio.types.lie import SE3

F64 = NDArray[np.float64]


class PoseStatus(Enum):
    """How a frame's final pose was obtained."""

    TRACKED = "tracked"
    INTERPOLATED = "interpolated"
    BRIDGED = "bridged"  # VIO: an IMU prediction for a frame the smoother did not get
    LOST = "lost"


@dataclass(frozen=True, slots=True)
class EstimatorReport:
    """What the estimator stages did at a frame: the initialisation attempt, the keyframe made
    (triangulation and BA reports), the camera-height reading, the visual-inertial stage's report;
    each None when it did not happen (``vio``: None without an IMU)."""

    init: InitResult | None = None
    keyframe: KeyframeReport | None = None
    scale: HeightEstimate | None = None
    vio: VioReport | None = None


@dataclass(frozen=True, slots=True)
class FrameRecord:
    """Everything the pipeline knows about one frame.

    ``status``: how the final pose was obtained; ``pose_online`` / ``pose_refined``: see the
    module docstring; ``segment``: the map segment of the pose (None before the first map);
    ``scale_factor``: metric scale applied to the frame's increments (1 without a scale source);
    ``events``: what happened, e.g. ``init_failed:low_parallax``, ``lost:too_few_inliers``;
    ``blur``: the blur gate's verdict; ``diagnostics``: the image health (None when off);
    ``tracking``: what the tracker did (None when tracking is off); ``estimator``: init,
    keyframe and scale reports.
    """

    index: int
    t_ns: int
    status: PoseStatus
    pose_online: SE3 | None
    pose_refined: SE3 | None
    segment: int | None
    scale_factor: float
    events: tuple[str, ...]
    blur: BlurResult
    diagnostics: FrameHealth | None
    tracking: TrackingReport | None
    estimator: EstimatorReport

    @property
    def is_keyframe(self) -> bool:
        return self.estimator.keyframe is not None

    @property
    def blurred(self) -> bool:
        return self.blur.is_blurred


@dataclass(frozen=True, slots=True)
class BodyTrajectory:
    """The visual-inertial trajectory: (N, 4, 4) ``T_world_body`` of the IMU body frame in the
    gravity-aligned metric world (z up), one per record, NaN where a frame has none; ``init_frame``:
    the record where the visual-inertial estimate started (frames before it are the VO's poses,
    put in that world by the initialisation's scale and gravity)."""

    T_world_body: F64
    init_frame: int


@dataclass(frozen=True, slots=True)
class PipelineOutput:
    """The run: one record per frame (final poses; a read-only sequence, kept on disk by
    :class:`~amrvio.pipeline.record_log.RecordLog`), the (N,) image times (ns), (N, 4, 4)
    ``T_world_cam`` of the refined trajectory, keyframe frame indices, (P, 3) map points, the
    camera-height readings, the per-frame scale, seconds per stage, the body trajectory of the
    visual-inertial run (None when it did not run or never initialised), and the wheels'
    calibration against it (None without wheel odometry or body trajectory)."""

    records: Sequence[FrameRecord]
    stamps_ns: NDArray[np.int64]
    T_world_cam: F64
    keyframe_indices: NDArray[np.int64]
    map_points: F64
    height_readings: tuple[HeightEstimate, ...]
    frame_scale: F64
    timings_s: dict[str, float]
    body: BodyTrajectory | None = None
    wheel_calibration: WheelCalibration | None = None


def reference_time(records: Sequence[FrameRecord], gap: int) -> int:
    """The time of the image the tracker tracks from, when the newest of ``records`` is ``gap``
    frames after it: a repeated frame (a recorder's duplicate) shows the image it repeats."""
    k = len(records) - 1 - gap
    while k > 0 and "repeated_frame" in records[k].events:
        k -= 1
    return records[max(k, 0)].t_ns


__all__ = ["BodyTrajectory", "EstimatorReport", "FrameRecord", "PipelineOutput", "PoseStatus", "reference_time"]
