"""Value types of the tracker stage: what it reads of a map (:class:`Landmarks`), what it made of
a frame (:class:`TrackOutcome`, :class:`TrackingReport`, :class:`TrackStep` with its inlier
:class:`Observations`), and its constant-velocity :class:`MotionModel`.

Poses are 4x4 ``T_cam_world`` arrays of the current map segment.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from enum import Enum
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


class PointLookup(Protocol):
    """Points by track id: ``xyz[ids]`` is (N, 3)."""

    def __getitem__(self, ids: I64) -> F64: ...


class Landmarks(Protocol):
    """What the tracker reads of a map: point positions by track id (``xyz[ids]``: (N, 3))."""

    @property
    def xyz(self) -> PointLookup: ...

    def points_of(self, track_ids: I64) -> NDArray[np.bool_]: ...

    def ensure_capacity(self, n_tracks: int) -> None: ...


class TrackOutcome(Enum):
    """What the tracker made of a frame."""

    STARTED = "started"  # a new reference image: tracks detected, no pose
    INIT_TRACKED = "init_tracked"  # tracked towards the initialisation reference, no pose yet
    SKIPPED_BLURRED = "skipped_blurred"  # blurred before the map exists: not used
    TRACKED = "tracked"  # PnP pose; tracks committed
    TRACKED_BLURRED = "tracked_blurred"  # PnP pose on a blurred frame; tracks not committed
    BLURRED_REFERENCE = "blurred_reference"  # PnP pose on a blurred frame that tracked as well as
    # a sharp one: tracks committed, the image is the new reference (no keyframe: it is blurred)
    PREDICTED = "predicted"  # blurred and PnP failed: the motion-model pose
    DIRECT = "direct_fallback"  # pose from direct alignment; tracks re-seeded from the map
    ROTATION = "rotation_only"  # too few map points, but one rotation explains the flow
    SCALED_RELATIVE = "scaled_relative"  # PnP failed: the tracks' essential matrix, scaled by
    # the map points that agree on the step length; tracks committed
    REPEATED = "repeated_frame"  # the image repeats the last one exactly: its pose, no tracking
    LOST = "lost"  # no pose: tracking must restart


@dataclass(frozen=True, slots=True)
class TrackingReport:
    """For the frame record: outcome, tracks alive after the frame, PnP inliers, the affine
    brightness change (a, b) used by KLT, whether direct alignment gave the prior, and the PnP
    status when PnP ran."""

    outcome: TrackOutcome
    n_tracks: int
    n_inliers: int
    brightness_a: float
    brightness_b: float
    direct_prior: bool
    pnp_status: str | None


@dataclass(frozen=True, slots=True)
class Observations:
    """PnP inlier tracks of a frame: ids (M,) and pixels (M, 2), for the final refinement."""

    ids: I64
    uv: F64


@dataclass(frozen=True, slots=True)
class TrackStep:
    """A tracked frame: the report, the pose ``T_cam_world`` (4x4; the prediction when the
    outcome has no measured pose) and the inlier observations when PnP succeeded."""

    report: TrackingReport
    T_cam_world: F64
    observations: Observations | None


class MotionModel:
    """Constant velocity: ``velocity`` = T_k_k-1 per frame, ``T_last`` = T_cam_world of the last
    good frame, and recent speeds in global units per frame (``speeds``)."""

    def __init__(self) -> None:
        self.velocity: F64 = np.eye(4)
        self.T_last: F64 | None = None
        self.speeds: deque[float] = deque(maxlen=50)

    def guess(self) -> F64:
        """Pose guess for a frame without a measurement."""
        return np.eye(4) if self.T_last is None else self.velocity @ self.T_last

    def typical_speed(self) -> float:
        """Median of the recent non-zero speeds (1.0 when there are none)."""
        moving = [v for v in self.speeds if v > 0]
        return float(np.median(moving)) if moving else 1.0


__all__ = ["Landmarks", "MotionModel", "Observations", "TrackOutcome", "TrackStep",
           "TrackingReport"]
