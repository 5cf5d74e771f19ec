"""The camera's motion as the VO knows it once a frame is tracked, for the translational smear.

The diagnostics run before tracking and predict the smear from the gyro (rotation only). Once the
frame has been tracked, the pipeline gives its pose and asks again with the map points of the
live tracks: the last ``HISTORY`` tracked poses of the current map segment give the velocity of
each interval at its mid-point, a least-squares line through them (constant acceleration) gives
the velocity at the frame's mid-exposure, and the points give the depths. A frame that was not
tracked (lost, blurred) takes the same line extrapolated to its time, up to ``MAX_AGE_FRAMES``
frame intervals after the last pose; a pose after a longer gap starts the history again from
the last pose before it (the one velocity across the gap averages what happened in it, better
than none while the new poses come). Velocity and depths are both in map
units and the translational smear depends only on their ratio, so the monocular scale cancels:
no metric scale is needed. The angular rate comes along for frames without gyro samples.

With an IMU the velocity comes instead from the poses of the last ``IMU_WINDOW_S`` and the
accelerometer between them (:mod:`amrvio.diagnostics.imu_vo_velocity`, still in VO units): a line
through velocities at 10-15 Hz cannot follow a hand shaking at 2-2.5 Hz. On the smear protocol
(``bench/bench_diagnostics.py``) the hand-held wall scan at 10 Hz went from 38 of 51 frames within
15 % (max 48.7 %, the VO's velocity 30-150 % off) to 51 of 51 (max 13.9 %), the hand-held room at
20 Hz from 109/110 (21.7 %) to 110/110 (10.3 %), the warehouse turn in place from 26/27 (18.1 %)
to 27/27 (10.8 %); the straight drives stay within 11.5 %.

The pipeline gives only the poses of frames tracked sharp: the poses of blurred frames (PnP on
blurred tracks, direct alignment, the motion model) are too rough to difference. Where the VO
has no motion (during and after a blur burst, after a loss), the VIO's prediction takes over
(:func:`motion_at_pose` with its velocity and landmarks, in metres).

On the simulator's 2.4 m corridor (376x240, 10 Hz, 20 ms exposures) every frame with more than
2 px of true smear is within 15 % once the map exists (max 14.3 % driving straight, 14.0 %
through a yaw burst of forward-stop-turn). Six velocities in the fit rather than four: the end
point of a line through four noisy velocities is no better than the last velocity alone (its
variance factor is 1.05 against 0.68 for six), and two straight-driving frames read 15-16 % low.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from amrvio.diagnostics.smear import CameraMotion
from amrvio.types.camera import CameraModel
from amrvio.types.lie import se3_matrix_inverse, so3_exp, so3_log

F64 = NDArray[np.float64]

MAX_POINTS = 300  # spread over the live tracks; the depth plane needs a few near each grid point
MIN_POINTS = 8
MAX_AGE_FRAMES = 2  # poses further apart than this many frame intervals are not differenced
HISTORY = 7  # poses kept: six velocities for the constant-acceleration fit
MIN_FIT = 4  # velocities needed for the fit (with fewer, the last velocity is used)
OUTLIER_K = 3.0  # robust sigmas beyond which an interval's velocity is left out of the fit
IMU_WINDOW_S = 1.0  # poses kept for the IMU-aided velocity (amrvio.diagnostics.imu_vo_velocity)

ImuVelocity = Callable[[list[tuple[int, F64]], int], "F64 | None"]
"""``(poses, t_ns) -> velocity``: the IMU-aided velocity of the camera at ``t_ns`` in VO units
(camera frame) from ``(t_ns, T_cam_world)`` poses, or None (see
:func:`~amrvio.diagnostics.imu_vo_velocity.imu_vo_velocity`)."""


class MotionHistory:
    """The last ``HISTORY`` tracked frames (a key and a time) of one map segment; a new segment
    starts the history again. Their poses are asked for when the motion
    is (``pose_of``), so that they are the map's current estimates: bundle adjustment moves a
    keyframe and the frames tracked against it, and poses kept from when they were tracked
    would jump against the newer ones (on the simulated warehouse drive one interval read twice
    the speed of its neighbours after each keyframe)."""

    def __init__(self) -> None:
        self._frames: deque[tuple[int, int]] = deque(maxlen=HISTORY)
        self._window: deque[tuple[int, int]] = deque()  # the last IMU_WINDOW_S, gaps and all
        self._segment: int | None = None

    def observe(self, t_ns: int, key: int | None, segment: int | None) -> None:
        """A frame that was tracked (``key``: what ``pose_of`` takes; None: the frame has no
        pose, the history stays, and ages)."""
        if segment is None or segment != self._segment:
            self._frames.clear()
            self._window.clear()
        self._segment = segment
        if key is not None and segment is not None:
            self._window.append((int(t_ns), int(key)))
            while self._window[0][0] < t_ns - IMU_WINDOW_S * 1e9:
                self._window.popleft()
            p = self._frames
            if len(p) >= 2 and (t_ns - p[-1][0]) > MAX_AGE_FRAMES * (p[-1][0] - p[-2][0]):
                # after a gap only its last pose before it stays: the one velocity across the
                # gap averages what happened meanwhile, better than none until new ones come
                while len(p) > 1:
                    p.popleft()
            p.append((int(t_ns), int(key)))

    def camera_motion(self, t_ns: int, pose_of: Callable[[int], F64 | None], points_world: F64,
                      camera: CameraModel, imu_velocity: ImuVelocity | None = None,
                      ) -> CameraMotion | None:
        """The camera's velocity (map units/s, camera frame) and angular rate at ``t_ns``, and
        the depths and pixels of the (N, 3) tracked map points ``points_world`` (same segment) in
        the predicted camera, or None when
        the last two poses are more than ``MAX_AGE_FRAMES`` intervals old, or too few points lie
        in front of the camera. ``pose_of(key)``: the frame's ``T_cam_world`` (4x4) in the
        segment as the map now has it (None: unknown; the frame is left out). ``imu_velocity``:
        when given and it has a velocity for the poses of the last ``IMU_WINDOW_S``, that
        velocity replaces the fit's."""
        p = [(t, T) for t, k in self._frames if (T := pose_of(k)) is not None]
        if len(p) < 2:
            return None
        t_last, T_last = p[-1]
        dt = (t_last - p[-2][0]) * 1e-9
        if not (0 < dt and (t_ns - t_last) * 1e-9 <= MAX_AGE_FRAMES * dt):
            return None
        # the velocity of each interval at its mid-point, in the last camera
        mids, vs, ws = [], [], []
        for (ta, Ta), (tb, Tb) in zip(p[:-1], p[1:], strict=True):
            v, w = _rates(Ta, Tb, (tb - ta) * 1e-9)
            R_lb = (T_last @ se3_matrix_inverse(Tb))[:3, :3]
            mids.append(0.5 * (ta + tb) * 1e-9)
            vs.append(R_lb @ v)
            ws.append(R_lb @ w)
        t_mid, V, W = np.array(mids), np.array(vs), np.array(ws)
        if len(mids) >= MIN_FIT:  # constant acceleration, least squares
            A = np.stack([np.ones_like(t_mid), t_mid - t_mid.mean()], axis=1)
            at = np.array([1.0, t_ns * 1e-9 - t_mid.mean()])
            Y = np.hstack([V, W])
            coef = np.linalg.lstsq(A, Y, rcond=None)[0]
            # an interval across a keyframe's bundle adjustment can read far off its neighbours:
            # intervals whose velocity lies beyond OUTLIER_K robust sigmas of the line are refitted
            # without (at most a third of them)
            r = np.linalg.norm((A @ coef - Y)[:, :3], axis=1)
            sigma = 1.4826 * float(np.median(r))
            keep = r <= OUTLIER_K * sigma
            if sigma > 0 and 3 * int(np.sum(~keep)) <= len(r) and int(np.sum(keep)) >= MIN_FIT - 1:
                coef = np.linalg.lstsq(A[keep], Y[keep], rcond=None)[0]
            vw = at @ coef
            v, w = vw[:3], vw[3:]
        else:
            v, w = V[-1], W[-1]
        # predicted pose of the coming frame at that motion
        h = (t_ns - t_last) * 1e-9
        R_step = np.asarray(so3_exp(w * h), dtype=np.float64)
        if imu_velocity is not None:
            window = [(t, T) for t, k in self._window if (T := pose_of(k)) is not None]
            v_imu = imu_velocity(window, t_ns) if window and window[-1][0] == t_last else None
            if v_imu is not None:  # in the camera at t_ns: back into the last camera's frame
                v = R_step @ v_imu
        T_step = np.eye(4)
        T_step[:3, :3] = R_step.T
        T_step[:3, 3] = -R_step.T @ (v * h)
        return motion_at_pose(T_step @ T_last, points_world, camera, R_step.T @ v, R_step.T @ w)


def _rates(T_a: F64, T_b: F64, dt: float) -> tuple[F64, F64]:
    """Velocity of the camera centre and angular rate, both in camera b, from ``T_cam_world`` at
    a and at b, ``dt`` seconds apart: camera b sees camera a's centre at ``t`` and its axes
    turned by ``R`` (``X_b = R X_a + t``), so b's centre moved by ``-t`` and turned by ``R^T``."""
    T_ba = T_b @ se3_matrix_inverse(T_a)
    R, t = T_ba[:3, :3], T_ba[:3, 3]
    return -t / dt, R @ so3_log(R.T) / dt


def motion_at_pose(T_cam_world: F64, points_world: F64, camera: CameraModel, v: F64,
                   w: F64 | None) -> CameraMotion | None:
    """The :class:`CameraMotion` of a camera at ``T_cam_world`` moving at ``v`` (camera frame,
    the points' units per second; ``w`` its angular rate or None), with the depths and pixels of
    the (N, 3) ``points_world`` it sees (up to ``MAX_POINTS``); None when fewer than
    ``MIN_POINTS`` of them are in front of it and inside the image."""
    T_pred = T_cam_world
    P = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
    if P.shape[0] < MIN_POINTS:
        return None
    X = P @ T_pred[:3, :3].T + T_pred[:3, 3]
    X = X[X[:, 2] > 1e-9]
    if X.shape[0] < MIN_POINTS or not (np.all(np.isfinite(v)) and (w is None or np.all(np.isfinite(w)))):
        return None
    uv = camera.project(X)
    inside = np.flatnonzero(camera.in_image(uv, border_px=0.5))  # pixel centres 0 .. W-1 (NaN: outside)
    if inside.size < MIN_POINTS:
        return None
    if inside.size > MAX_POINTS:  # thinned among the points in view, not before: a window's
        # landmarks are mostly out of view after a turn, and thinning them first left half as
        # many in view (the smear 16 % low after a yaw burst)
        inside = inside[np.linspace(0, inside.size - 1, MAX_POINTS).round().astype(np.int64)]
    return CameraMotion(v, X[inside, 2], uv[inside], w)


__all__ = ["MAX_POINTS", "MotionHistory", "motion_at_pose"]
