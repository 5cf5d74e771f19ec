"""The smear's translational part inside the frame loop (issue 13): which motion it comes from.

The diagnostics predict a frame's smear from the gyro before tracking; once the frame has been
tracked the pipeline adds the camera's translation, from one of two sources:

1. the VIO, while it runs: its newest state propagated through the frame's IMU samples gives the
   velocity at the frame (metric, the lever arm of the body's rotation included) and its
   window's landmarks the depths (metres). It follows the motion at the IMU's rate, through
   blur bursts and tracking losses. It is used only while its newest update passed its
   consistency checks and its velocity's standard deviation is at most ``MAX_REL_SIGMA`` of the
   speed (or ``MAX_SIGMA_M_S``): after a re-initialisation its velocity can be far off;
2. otherwise the VO: the velocity from its recent sharp poses (with the IMU's accelerometer in
   between when there is one, in the VO's units) and the depths of its tracked map points
   (:mod:`amrvio.diagnostics.vo_motion`).

Measured on the simulator (376x240, 6 s, ``bench/bench_diagnostics.py``'s smear protocol): with
the VO alone, the frames of a yaw burst in forward-stop-turn read 31-63 % low (the VO lost them);
with the VIO first, as here, every frame with more than 2 px of true smear is within 15 %.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from amrvio.diagnostics.frame import FrameDiagnostics
from amrvio.diagnostics.health import FrameHealth
from amrvio.estimator.vo_map import VoMap
from amrvio.frontend.tracking_types import TrackOutcome
from amrvio.frontend.tracks import TrackSet
from amrvio.pipeline.vio_stage import VioStage
from amrvio.types.sensors import ImuData

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

MAX_REL_SIGMA = 0.1
MAX_SIGMA_M_S = 0.05
ROUGH_POSES = (TrackOutcome.TRACKED_BLURRED, TrackOutcome.BLURRED_REFERENCE, TrackOutcome.PREDICTED,
               TrackOutcome.DIRECT)
"""Tracking outcomes whose poses are too rough to difference into a velocity: those of blurred
frames (PnP on blurred tracks, the motion model, direct alignment)."""


def vio_camera_motion(stage: VioStage, t_ns: int, imu: ImuData | None,
                      tracks: TrackSet) -> tuple[F64, F64, F64] | None:
    """The camera's motion at ``t_ns`` as the running smoother predicts it from its newest state
    and the IMU since (``imu``: the frame's samples, added to the stage's log): ``T_cam_world``
    (4x4, metric world), the velocity of the camera centre in the camera frame (m/s) and the
    window's landmarks (L, 3), world metres, less those that a live track of ``tracks`` puts
    beyond the smoother's gate (:meth:`VioBackend.landmarks_agreeing`). None before the start,
    when the IMU does not reach ``t_ns``, or when the estimate is not to be trusted with it (see
    the module docstring). The prediction is the one the stage starts from for the same frame
    (propagation is idempotent)."""
    if not stage.running or not stage.track.consistent:
        return None
    span = stage.frame_imu(t_ns, imu)
    if len(span) == 0:
        return None
    est = stage.backend.propagate(t_ns, span)
    st = est.state
    if not est.ok or st is None:
        return None
    speed = float(np.linalg.norm(st.v_world_m_s))
    if est.velocity_sigma_m_s is not None and float(np.linalg.norm(est.velocity_sigma_m_s)) > max(
            MAX_REL_SIGMA * speed, MAX_SIGMA_M_S):
        return None
    T_wc = st.T_world_body @ stage.setup.T_body_cam
    k = int(np.argmin(np.abs(np.asarray(span.stamps_ns) - t_ns)))
    w_body = np.asarray(span.gyro_rad_s[k]) - np.asarray(st.bias.gyro_rad_s)
    t_bc = np.asarray(stage.setup.T_body_cam.t)
    v_cam_world = np.asarray(st.v_world_m_s) + st.T_world_body.R @ np.cross(w_body, t_bc)
    X = stage.backend.landmarks_agreeing(T_wc, tracks.ids, tracks.pts)
    return T_wc.inverse().matrix(), T_wc.R.T @ v_cam_world, X


def with_translation(diag: FrameDiagnostics, health: FrameHealth, vio: VioStage | None, t_ns: int,
                     imu: ImuData | None, vo_map: VoMap | None, tracks: TrackSet,
                     pose_of: Callable[[int], F64 | None]) -> FrameHealth:
    """``health`` with the smear's translational part: the VIO's motion when it has one, else
    the VO's (``vo_map``: the current map, None before one; ``tracks``: the live tracks,
    whose map points give the depths; ``pose_of``: a tracked frame's current ``T_cam_world`` in
    the map, see :meth:`FrameDiagnostics.with_vo_motion`)."""
    motion = None if vio is None else vio_camera_motion(vio, t_ns, imu, tracks)
    if motion is not None:
        health = diag.with_pose_motion(health, *motion)
    if health.blur.smear_px_translation is None and vo_map is not None:
        points = vo_map.xyz[tracks.ids[vo_map.points_of(tracks.ids)]]
        health = diag.with_vo_motion(health, pose_of, points)
    return health


__all__ = ["MAX_REL_SIGMA", "MAX_SIGMA_M_S", "ROUGH_POSES", "vio_camera_motion", "with_translation"]
