"""Simulated sequences with their ground truth, and the oracles of bench_diag_truth.

A sequence is rendered with the simulator's own parts (motion, SceneRenderer, render_frame with
motion blur, the sensor model, the synthetic IMU with ADIS16448 noise) and keeps what the files
of ``amrvio simulate`` do not: the depth map and the camera pose of every frame. The oracles say,
from that truth alone, whether the failure a flag is about happened at a frame:

- tracking (blur): LK (the library's tracker, default settings) from the previous frame on
  Shi-Tomasi corners; a track is good when it is kept and ends within ``GOOD_TRACK_PX`` of the
  true projection (rendered depth and poses). The frame fails when fewer than
  ``MIN_GOOD_FRACTION`` of the corners visible in both frames are good;
- initialisation (parallax): the library's two-view initialiser with the VO initialiser's gates
  (3 deg of parallax), between an earlier frame and the frame, on true correspondences with
  0.5 px noise. It fails when it returns no pose or a translation direction
  more than ``MAX_DIRECTION_DEG`` off;
- scale (excitation): the linear visual-inertial alignment (Mur-Artal and Tardos 2017, VINS-Mono's
  LinearAlignment without refinement) over the excitation window: keyframes at 5 Hz whose
  positions are known up to scale (2 mm noise) and rotation, the noisy biased IMU integrated
  between them, unknown scale, velocities and gravity. It fails when the scale is more than
  ``MAX_SCALE_ERROR`` off.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from amrvio.geometry.two_view import TwoViewConfig, two_view_init
from amrvio.photometric.model import RadialVignette
from amrvio.sim.exposure_control import ExposureLimits, scripted_exposures
from amrvio.sim.image_formation import CameraResponse, SensorModel, render_frame
from amrvio.sim.imu_synth import synthesize_imu
from amrvio.sim.motion import Motion, default_T_body_cam
from amrvio.sim.render import SceneRenderer
from amrvio.sim.replay import make_replay_motion
from amrvio.sim.scene import Scene
from amrvio.tracking.detect import DetectorConfig, detect_corners
from amrvio.tracking.lk import LkConfig, LkTracker
from amrvio.types.camera import CameraModel
from amrvio.types.lie import SE3
from amrvio.types.sensors import ImuData, ImuNoise

F64 = NDArray[np.float64]
U8 = NDArray[np.uint8]

GOOD_TRACK_PX = 1.5
MIN_GOOD_FRACTION = 0.7
MAX_DIRECTION_DEG = 5.0
MAX_SCALE_ERROR = 0.05
START_NS = 1_000_000_000


@dataclass(frozen=True, slots=True, eq=False)
class SimFrame:
    """One rendered frame: the image, its mid-exposure stamp, exposure, camera pose and depth."""

    image: U8
    t_ns: int
    exposure_s: float
    T_world_cam: SE3
    depth: NDArray[np.float32]
    smear_px: float


@dataclass(frozen=True, slots=True, eq=False)
class SimSequence:
    camera: CameraModel
    T_body_cam: SE3
    frames: tuple[SimFrame, ...]
    imu: ImuData
    motion: Motion
    pose_at: Callable[[float], SE3]
    gyro_bias: F64  # the IMU's true initial gyro bias (a still start lets a pipeline estimate it)


def straight_motion(duration_s: float, speed: Callable[[F64], F64],
                    yaw: Callable[[F64], F64], start_xy: tuple[float, float] = (0.0, 0.0),
                    height_m: float = 0.5) -> Motion:
    """A drive along +x at ``speed(t)`` (m/s) with heading ``yaw(t)`` (rad), as a replayed
    trajectory sampled at 200 Hz (the spline gives the IMU exact derivatives)."""
    margin = 1.5
    t = np.arange(-margin, duration_s + margin, 0.005)
    v = speed(t)
    s = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))])
    s -= s[np.searchsorted(t, 0.0)]
    pos = np.stack([start_xy[0] + s, np.full_like(s, start_xy[1]), np.full_like(s, height_m)], 1)
    psi = yaw(t)
    quats = np.stack([np.cos(psi / 2), np.zeros_like(psi), np.zeros_like(psi), np.sin(psi / 2)], 1)
    stamps = START_NS + np.round(t * 1e9).astype(np.int64)
    return make_replay_motion(stamps, pos, quats, start_s=margin, duration_s=duration_s)


def render_sequence(scene: Scene, camera: CameraModel, motion: Motion, fps: float,
                    exposure_s: float, ev_steps: Sequence[tuple[float, float]] = (),
                    seed: int = 0, blur: bool = True) -> SimSequence:
    """Render ``motion`` in ``scene`` at ``fps`` (stamps at mid-exposure, as ``amrvio simulate``)
    with scripted EV steps, and synthesise its IMU (ADIS16448 noise and random biases)."""
    rng = np.random.default_rng(seed)
    T_body_cam = default_T_body_cam(10.0)
    renderer = SceneRenderer(scene, camera)

    def pose_at(t: float) -> SE3:
        return motion.T_world_body(t) @ T_body_cam

    n = int(math.floor(motion.duration_s * fps + 1e-9))
    t_frames = (np.arange(n) + 0.5) / fps
    expos = scripted_exposures(t_frames, exposure_s, tuple(ev_steps),
                               ExposureLimits(frame_period_s=1.0 / fps))
    sensor = SensorModel(1.0, CameraResponse(1.0), RadialVignette(-0.25))
    frames = []
    for k in range(n):
        e = round(float(expos[k]) * 1e6) / 1e6
        f = render_frame(renderer, pose_at, float(t_frames[k]) - 0.5 * e, e, sensor, rng, blur=blur)
        frames.append(SimFrame(f.image, START_NS + int(round(t_frames[k] * 1e9)), e,
                               f.T_world_cam_mid, renderer.depth(f.T_world_cam_mid),
                               f.smear_px_max))
    noise = ImuNoise.euroc_adis16448()
    syn = synthesize_imu(motion, 200.0, noise, rng, START_NS, rng.standard_normal(3) * 0.005,
                         rng.standard_normal(3) * 0.05)
    return SimSequence(camera, T_body_cam, tuple(frames), syn.imu, motion, pose_at,
                       np.asarray(syn.gyro_bias[0], dtype=np.float64))


def _true_matches(seq: SimSequence, i: int, j: int, pts_i: F64) -> tuple[F64, F64]:
    """Frame-i pixels (N, 2) -> their true pixels in frame j; NaN where not seen in both (behind,
    outside, or occluded in j by more than 5 % of the depth)."""
    cam, fi, fj = seq.camera, seq.frames[i], seq.frames[j]
    ij = np.rint(pts_i).astype(int)
    ij[:, 0] = np.clip(ij[:, 0], 0, cam.width - 1)
    ij[:, 1] = np.clip(ij[:, 1], 0, cam.height - 1)
    z = fi.depth[ij[:, 1], ij[:, 0]].astype(np.float64)
    X_i = cam.unproject(pts_i) * z[:, None]
    T_j_i = fj.T_world_cam.inverse() @ fi.T_world_cam
    X_j = X_i @ T_j_i.R.T + T_j_i.t
    uv = cam.project(X_j)
    out = np.full_like(pts_i, np.nan)
    ok = np.isfinite(z) & np.all(np.isfinite(uv), axis=1)
    ok &= (uv[:, 0] >= 0) & (uv[:, 0] <= cam.width - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= cam.height - 1)
    if np.any(ok):
        q = np.rint(uv[ok]).astype(int)
        zj = fj.depth[q[:, 1], q[:, 0]]
        ok[np.flatnonzero(ok)] = np.abs(zj - X_j[ok, 2]) <= 0.05 * X_j[ok, 2]
    out[ok] = uv[ok]
    return out, X_j


def tracking_failure(seq: SimSequence, k: int) -> tuple[bool, float]:
    """(failed, good fraction) of LK from frame k-1 to k (see the module docstring)."""
    prev, cur = seq.frames[k - 1].image, seq.frames[k].image
    pts = detect_corners(prev, DetectorConfig(max_corners=200, quality_level=0.01,
                                              min_distance_px=8, block_size=5))
    truth, _ = _true_matches(seq, k - 1, k, pts)
    seen = np.all(np.isfinite(truth), axis=1)
    if int(seen.sum()) < 10:
        return True, 0.0
    cam = seq.camera
    K = np.array([[cam.fx, 0, cam.cx], [0, cam.fy, cam.cy], [0, 0, 1.0]])
    res = LkTracker(LkConfig()).track(prev, cur, pts[seen], K=K)
    err = np.linalg.norm(res.pts - truth[seen], axis=1)
    good = float(np.mean(res.ok & (err < GOOD_TRACK_PX)))
    return good < MIN_GOOD_FRACTION, good


def init_failure(seq: SimSequence, ref: int, k: int, seed: int = 0) -> bool:
    """Whether the VO's two-view initialiser fails between frames ``ref`` and ``k``."""
    if k == ref:
        return True
    cam = seq.camera
    uu, vv = np.meshgrid(np.arange(6, cam.width, 12), np.arange(6, cam.height, 12))
    grid = np.stack([uu.ravel(), vv.ravel()], axis=1).astype(np.float64)
    uv, _ = _true_matches(seq, ref, k, grid)
    ok = np.all(np.isfinite(uv), axis=1)
    rng = np.random.default_rng(seed + 1000 * k)
    p1 = grid[ok] + rng.normal(0.0, 0.5, (int(ok.sum()), 2))
    p2 = uv[ok] + rng.normal(0.0, 0.5, (int(ok.sum()), 2))
    K = np.array([[cam.fx, 0, cam.cx], [0, cam.fy, cam.cy], [0, 0, 1.0]])
    res = two_view_init(p1, p2, K, TwoViewConfig(min_parallax_deg=3.0))
    if not res.ok:
        return True
    T_k_ref = seq.frames[k].T_world_cam.inverse() @ seq.frames[ref].T_world_cam
    t_true = T_k_ref.t / max(float(np.linalg.norm(T_k_ref.t)), 1e-12)
    t_est = res.T_c2_c1[:3, 3] / max(float(np.linalg.norm(res.T_c2_c1[:3, 3])), 1e-12)
    ang = math.degrees(math.acos(float(np.clip(t_true @ t_est, -1.0, 1.0))))
    return ang > MAX_DIRECTION_DEG


def vi_scale_error(motion: Motion, imu: ImuData, t0_s: float, t1_s: float, kf_hz: float = 5.0,
                   seed: int = 0, pos_noise_m: float = 0.002) -> float:
    """|s_est / s - 1| of the linear visual-inertial alignment over [t0_s, t1_s] (module
    docstring), on keyframes at ``kf_hz``. Keyframe positions are the body's (world frame),
    divided by a scale of 3 and perturbed by ``pos_noise_m`` (in metres of the true scale); the
    IMU is the sequence's (noisy, biased), rotated into the world by the true attitude."""
    s_true = 1.0 / 3.0
    rng = np.random.default_rng(seed)
    tk = np.arange(t0_s, t1_s + 1e-9, 1.0 / kf_hz)
    st = motion.states(tk)
    p_vo = st.p_world * s_true + rng.normal(0.0, pos_noise_m * s_true, st.p_world.shape)
    t_imu = (imu.stamps_ns - START_NS).astype(np.float64) * 1e-9
    sel = (t_imu >= tk[0] - 0.01) & (t_imu <= tk[-1] + 0.01)
    ti, acc = t_imu[sel], imu.accel_m_s2[sel]
    a_w = np.einsum("nij,nj->ni", motion.states(ti).R_world_body, acc)  # R f, gravity inside
    n = tk.size
    rows, rhs = [], []
    # unknowns: s (1/s_true scale on p_vo), g (3), v_k (3 n)
    for k in range(n - 1):
        m = (ti >= tk[k] - 1e-6) & (ti <= tk[k + 1] + 1e-6)
        tt, aa = ti[m], a_w[m]
        if tt.size < 3:
            continue
        dt = np.diff(tt)
        dv = np.concatenate([np.zeros((1, 3)), np.cumsum(0.5 * (aa[1:] + aa[:-1]) * dt[:, None], 0)])
        dp = np.sum(0.5 * (dv[1:] + dv[:-1]) * dt[:, None], axis=0)
        T = tk[k + 1] - tk[k]
        # p_{k+1} = p_k + v_k T + g T^2/2 + dp ;  v_{k+1} = v_k + g T + dv
        for ax in range(3):
            r = np.zeros(4 + 3 * n)
            r[0] = p_vo[k + 1, ax] - p_vo[k, ax]
            r[1 + ax] = -0.5 * T * T
            r[4 + 3 * k + ax] = -T
            rows.append(r)
            rhs.append(dp[ax])
            r = np.zeros(4 + 3 * n)
            r[1 + ax] = -T
            r[4 + 3 * (k + 1) + ax] = 1.0
            r[4 + 3 * k + ax] = -1.0
            rows.append(r)
            rhs.append(dv[-1, ax])
    A, b = np.array(rows), np.array(rhs)
    x, *_ = np.linalg.lstsq(A, b, rcond=None)
    return abs(float(x[0]) * s_true - 1.0)


__all__ = ["SimFrame", "SimSequence", "init_failure", "render_sequence", "straight_motion",
           "tracking_failure", "vi_scale_error"]
