"""The camera's motion as the VO knows it once a frame is tracked, for the translational smear.

The diagnostics run before tracking and predict the smear from the gyro (rotation only). Once the
frame has been tracked, the pipeline gives its pose and asks again with the map points of the
live tracks: the last ``HISTORY`` tracked poses of the current map segment give the velocity of
each interval at its mid-point, a least-squares line through them (constant acceleration) gives
the velocity at the frame's mid-exposure, and the points give the depths. A frame that was not
tracked (lost, blurred) takes the same line extrapolated to its time, up to ``MAX_AGE_FRAMES``
frame intervals after the last pose. Velocity and depths are both in map units and the
translational smear depends only on their ratio, so the monocular scale cancels: no metric
scale is needed. The angular rate comes along for frames without gyro samples.

On the simulator's 2.4 m corridor (376x240, 10 Hz, 20 ms exposures) every frame with more than
2 px of true smear is within 15 % once the map exists, driving straight; the velocity of the
last interval alone lags by half a frame and read 15-16 % low on two frames.
"""

from __future__ import annotations

from collections import deque

import numpy as np
from numpy.typing import NDArray

from amrvio.diagnostics.smear import CameraMotion
from amrvio.types.camera import CameraModel
from amrvio.types.lie import se3_matrix_inverse, so3_exp, so3_log

F64 = NDArray[np.float64]

MAX_POINTS = 300  # spread over the live tracks; the depth plane needs a few near each grid point
MIN_POINTS = 8
MAX_AGE_FRAMES = 2  # poses further apart than this many frame intervals are not differenced
HISTORY = 5  # poses kept: four velocities for the constant-acceleration fit
MIN_FIT = 4  # velocities needed for the fit (with fewer, the last velocity is used)


class MotionHistory:
    """The last ``HISTORY`` tracked camera poses (``T_cam_world`` of one map segment) and their
    times; a new segment starts the history again."""

    def __init__(self) -> None:
        self._poses: deque[tuple[int, F64]] = deque(maxlen=HISTORY)
        self._segment: int | None = None

    def observe(self, t_ns: int, T_cam_world: F64 | None, segment: int | None) -> None:
        """A frame's tracked pose (None: the frame has none; the history stays, and ages)."""
        if segment is None or segment != self._segment:
            self._poses.clear()
        self._segment = segment
        if T_cam_world is not None and segment is not None:
            self._poses.append((int(t_ns), np.array(T_cam_world, dtype=np.float64)))

    def camera_motion(self, t_ns: int, points_world: F64, camera: CameraModel
                      ) -> CameraMotion | None:
        """The camera's velocity (map units/s, camera frame) and angular rate at ``t_ns``, and
        the depths and pixels of the (N, 3) tracked map points ``points_world`` (same segment) in
        the predicted camera, or None when
        the last two poses are more than ``MAX_AGE_FRAMES`` intervals old, or too few points lie
        in front of the camera."""
        p = list(self._poses)
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
            coef = np.linalg.lstsq(A, np.hstack([V, W]), rcond=None)[0]
            vw = at @ coef
            v, w = vw[:3], vw[3:]
        else:
            v, w = V[-1], W[-1]
        # predicted pose of the coming frame at that motion
        h = (t_ns - t_last) * 1e-9
        R_step = np.asarray(so3_exp(w * h), dtype=np.float64)
        T_step = np.eye(4)
        T_step[:3, :3] = R_step.T
        T_step[:3, 3] = -R_step.T @ (v * h)
        return _points(T_step @ T_last, points_world, camera, R_step.T @ v, R_step.T @ w)


def _rates(T_a: F64, T_b: F64, dt: float) -> tuple[F64, F64]:
    """Velocity of the camera centre and angular rate, both in camera b, from ``T_cam_world`` at
    a and at b, ``dt`` seconds apart: camera b sees camera a's centre at ``t`` and its axes
    turned by ``R`` (``X_b = R X_a + t``), so b's centre moved by ``-t`` and turned by ``R^T``."""
    T_ba = T_b @ se3_matrix_inverse(T_a)
    R, t = T_ba[:3, :3], T_ba[:3, 3]
    return -t / dt, R @ so3_log(R.T) / dt


def _points(T_pred: F64, points_world: F64, camera: CameraModel, v: F64,
            w: F64) -> CameraMotion | None:
    P = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
    if P.shape[0] < MIN_POINTS:
        return None
    if P.shape[0] > MAX_POINTS:
        P = P[np.linspace(0, P.shape[0] - 1, MAX_POINTS).round().astype(np.int64)]
    X = P @ T_pred[:3, :3].T + T_pred[:3, 3]
    X = X[X[:, 2] > 1e-9]
    if X.shape[0] < MIN_POINTS or not (np.all(np.isfinite(v)) and np.all(np.isfinite(w))):
        return None
    uv = camera.project(X)
    inside = camera.in_image(uv, border_px=0.5)  # pixel centres 0 .. W-1 (NaN: outside)
    if int(inside.sum()) < MIN_POINTS:
        return None
    return CameraMotion(v, X[inside, 2], uv[inside], w)


__all__ = ["MAX_POINTS", "MotionHistory"]
