"""The IMU window of a frame: bounds in closed form on a regular 200 Hz stream."""

from __future__ import annotations

import numpy as np

from amrvio.imu.window import FIRST_FRAME_LOOKBACK_NS, MARGIN_NS, frame_imu_window
from amrvio.pipeline.imu_log import ImuLog
from amrvio.types.lie import so3_exp
from amrvio.types.sensors import ImuData

DT = 5_000_000  # 200 Hz
T0 = 1_000_000_000_000


def _imu(n: int = 2000) -> ImuData:
    t = T0 + DT * np.arange(n, dtype=np.int64)
    return ImuData(t, np.zeros((n, 3)), np.tile([0.0, 0.0, 9.81], (n, 1)))


def test_window_between_frames_reaches_mid_exposure_with_margins() -> None:
    imu = _imu()
    prev, t, exposure = T0 + 1_000_000_000, T0 + 1_050_000_000, 0.008
    win = frame_imu_window(imu, t, prev, exposure)
    lo, hi = prev - MARGIN_NS, t + 4_000_000 + MARGIN_NS
    expected = imu.stamps_ns[(imu.stamps_ns >= lo) & (imu.stamps_ns <= hi)]
    np.testing.assert_array_equal(win.stamps_ns, expected)
    assert win.stamps_ns[0] == prev - 10_000_000 and win.stamps_ns[-1] == t + 10_000_000  # on grid
    assert len(win) == (hi - lo) // DT + 1


def test_first_frame_looks_back_two_seconds() -> None:
    imu = _imu()
    t = T0 + 5_000_000_000
    win = frame_imu_window(imu, t, None, 0.0)
    assert win.stamps_ns[0] == t - FIRST_FRAME_LOOKBACK_NS - MARGIN_NS
    assert win.stamps_ns[-1] == t + MARGIN_NS


def test_window_before_the_stream_is_empty() -> None:
    win = frame_imu_window(_imu(), T0 - 3_000_000_000, None, 0.01)
    assert len(win) == 0


def test_imu_log_rotation_is_the_gyro_integral_in_the_camera_frame() -> None:
    # a constant 0.8 rad/s about the body z axis for 0.25 s, camera x = body z: the camera turns
    # 0.2 rad about its x axis; R_cam1_cam0 is the transpose of exp(0.2 [x]^)
    t = np.arange(0, 1_000_000_001, 5_000_000, dtype=np.int64)
    gyro = np.tile([0.0, 0.0, 0.8], (t.size, 1)) + [0.01, -0.02, 0.03]
    log = ImuLog(keep_s=5.0)
    log.add(ImuData(t, gyro, np.zeros((t.size, 3))))
    R_cam_body = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    R = log.rotation(300_000_000, 550_000_000, R_cam_body, np.array([0.01, -0.02, 0.03]))
    assert R is not None
    np.testing.assert_allclose(R, so3_exp(np.array([0.2, 0.0, 0.0])).T, atol=1e-12)
    assert log.rotation(300_000_000, 1_500_000_000, R_cam_body, None) is None  # beyond the log
