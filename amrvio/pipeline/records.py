"""The per-frame record: one :class:`FrameRecord` per frame, owned by the pipeline, carrying each
stage's report. It is the single source of ``health.csv``, the trajectory and the summary.

Poses are ``SE3`` values, ``T_world_cam`` (camera pose in the world). ``pose_online`` is the pose
known when the frame was processed (causal); ``pose_refined`` is the pose after the run, from the
bundle-adjusted keyframes (None for a frame that never got one).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

import numpy as np
from numpy.typing import NDArray

from amrvio.diagnostics.blur import BlurResult
from amrvio.diagnostics.frame import FrameHealth
from amrvio.estimator.camera_height import HeightEstimate
from amrvio.estimator.initializer import InitResult
from amrvio.estimator.local_mapping import KeyframeReport
from amrvio.frontend.tracker import TrackingReport
from amrvio.types.lie import SE3

F64 = NDArray[np.float64]


class PoseStatus(Enum):
    """How a frame's final pose was obtained."""

    TRACKED = "tracked"
    INTERPOLATED = "interpolated"
    LOST = "lost"


@dataclass(frozen=True, slots=True)
class EstimatorReport:
    """What the estimator stages did at a frame: the initialisation attempt, the keyframe made
    (triangulation and BA reports), the camera-height reading; each None when it did not
    happen."""

    init: InitResult | None = None
    keyframe: KeyframeReport | None = None
    scale: HeightEstimate | None = None


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
class PipelineOutput:
    """The run: one record per frame (final poses), (N, 4, 4) ``T_world_cam`` of the refined
    trajectory, keyframe frame indices, (P, 3) map points, the camera-height readings, the
    per-frame scale and seconds per stage."""

    records: tuple[FrameRecord, ...]
    T_world_cam: F64
    keyframe_indices: NDArray[np.int64]
    map_points: F64
    height_readings: tuple[HeightEstimate, ...]
    frame_scale: F64
    timings_s: dict[str, float]

    @property
    def stamps_ns(self) -> NDArray[np.int64]:
        return np.array([r.t_ns for r in self.records], dtype=np.int64)


__all__ = ["EstimatorReport", "FrameRecord", "PipelineOutput", "PoseStatus"]
