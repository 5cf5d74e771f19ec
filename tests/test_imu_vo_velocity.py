"""The IMU-aided velocity in VO units (amrvio.diagnostics.imu_vo_velocity) against a closed-form
motion: a body shaking at 2.5 Hz while it drifts and turns, filmed at 10 Hz, its poses given in an
unknown VO frame (rotated, shifted and scaled by 7.5 units per metre)."""

from __future__ import annotations

import numpy as np
import pytest

from amrvio.diagnostics.imu_vo_velocity import imu_vo_velocity
from amrvio.diagnostics.vo_motion import HISTORY, MotionHistory
from amrvio.types.camera import PinholeCamera
from amrvio.types.lie import so3_exp
from amrvio.types.sensors import ImuData

MU = 7.5  # VO units per metre
R_VW = so3_exp(np.array([0.4, -1.0, 0.7]))  # the VO world's axes against the true world's
O_V = np.array([3.0, -1.0, 2.0])
R_BC = so3_exp(np.array([-1.2, 0.1, -1.5]))  # camera axes in the body
P_BC = np.array([0.05, -0.02, 0.03])  # camera centre in the body (m)
R_0 = so3_exp(np.array([0.2, -0.15, 0.0]))  # a tilt: gravity is not along a body axis
G_W = np.array([0.0, 0.0, -9.81])
F_HZ, AMP = 2.5, np.array([0.02, 0.012, 0.015])  # hand jitter (m)
V_DRIFT = np.array([0.1, 0.05, 0.0])
W_HZ, YAW = 1.5, 0.08


def _state(t: float, shake: float = 1.0) -> tuple[np.ndarray, ...]:
    """p_b, v_b, a_b (world), R_wb, omega_b at time t (s)."""
    ph = 2 * np.pi * F_HZ * t
    p = V_DRIFT * t + shake * AMP * np.sin(ph)
    v = V_DRIFT + shake * AMP * 2 * np.pi * F_HZ * np.cos(ph)
    a = -shake * AMP * (2 * np.pi * F_HZ) ** 2 * np.sin(ph)
    phi = YAW * np.sin(2 * np.pi * W_HZ * t)
    dphi = YAW * 2 * np.pi * W_HZ * np.cos(2 * np.pi * W_HZ * t)
    R = R_0 @ so3_exp(np.array([0.0, 0.0, phi]))
    return p, v, a, R, np.array([0.0, 0.0, dphi])


def _imu(t0: float, t1: float, shake: float) -> ImuData:
    ts = np.arange(t0, t1 + 1e-9, 0.005)
    gyro, acc = [], []
    for t in ts:
        _, _, a, R, w = _state(t, shake)
        gyro.append(w)
        acc.append(R.T @ (a - G_W))
    return ImuData(np.round(ts * 1e9).astype(np.int64), np.array(gyro), np.array(acc))


def _T_cam_vo(t: float, shake: float) -> np.ndarray:
    p, _, _, R, _ = _state(t, shake)
    c_v = MU * R_VW @ (p + R @ P_BC) + O_V
    R_vc = R_VW @ R @ R_BC
    T = np.eye(4)
    T[:3, :3] = R_vc.T
    T[:3, 3] = -R_vc.T @ c_v
    return T


def _v_cam_vo(t: float, shake: float) -> np.ndarray:
    """The camera centre's velocity in its own frame, VO units/s (the truth)."""
    _, v, _, R, w = _state(t, shake)
    return MU * (R @ R_BC).T @ (v + R @ np.cross(w, P_BC))


FRAMES_S = np.arange(0.0, 1.05, 0.1) + 0.3  # 11 poses at 10 Hz, the last at 1.3 s


@pytest.mark.parametrize("shake", [1.0, 0.0])
def test_velocity_in_vo_units_follows_the_hand(shake: float) -> None:
    imu = _imu(0.0, 1.4, shake)
    poses = [(int(round(t * 1e9)), _T_cam_vo(t, shake)) for t in FRAMES_S]
    t_ns = poses[-1][0]
    v = imu_vo_velocity(poses, t_ns, imu, R_BC.T, P_BC)
    truth = _v_cam_vo(FRAMES_S[-1], shake)
    assert v is not None
    # with the shake the velocity turns within a frame interval; without it MU is unobservable
    # but the velocity is still right
    assert np.linalg.norm(v - truth) <= 0.02 * np.linalg.norm(truth)


def test_the_pose_fit_alone_lags_the_hand_and_the_imu_does_not() -> None:
    """Through :class:`MotionHistory`: the constant-acceleration line through the last poses'
    velocities is far off at 2.5 Hz; with the IMU the motion's velocity is the truth's."""
    cam = PinholeCamera(376, 240, 230.0, 230.0, 188.0, 120.0)
    imu = _imu(0.0, 1.4, 1.0)
    h = MotionHistory()
    poses: dict[int, np.ndarray] = {}
    for k, t in enumerate(FRAMES_S):
        poses[k] = _T_cam_vo(t, 1.0)
        h.observe(int(round(t * 1e9)), k, segment=0)
    t_ns = int(round(FRAMES_S[-1] * 1e9))
    T = poses[len(FRAMES_S) - 1]
    pts_cam = np.stack(np.meshgrid(np.linspace(-2, 2, 6), np.linspace(-1, 1, 5), [4.0]), -1)
    pts_cam = pts_cam.reshape(-1, 3) * MU
    pts_world = (pts_cam - T[:3, 3]) @ T[:3, :3]  # X_w = R^T (X_c - t)
    truth = _v_cam_vo(FRAMES_S[-1], 1.0)
    plain = h.camera_motion(t_ns, poses.get, pts_world, cam)
    aided = h.camera_motion(t_ns, poses.get, pts_world, cam, lambda p, t: imu_vo_velocity(
        p, t, imu, R_BC.T, P_BC))
    assert plain is not None and aided is not None and len(poses) > HISTORY
    assert np.linalg.norm(plain.velocity_cam_m_s - truth) > 0.2 * np.linalg.norm(truth)
    assert np.linalg.norm(aided.velocity_cam_m_s - truth) <= 0.02 * np.linalg.norm(truth)


def test_too_few_poses_or_no_imu_cover_give_none() -> None:
    imu = _imu(0.5, 1.4, 1.0)  # starts after the first pose
    poses = [(int(round(t * 1e9)), _T_cam_vo(t, 1.0)) for t in FRAMES_S]
    assert imu_vo_velocity(poses, poses[-1][0], imu, R_BC.T, P_BC) is None
    assert imu_vo_velocity(poses[-4:], poses[-1][0], imu, R_BC.T, P_BC) is None
