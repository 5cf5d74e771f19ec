"""The visual-inertial stage of the frame loop (issue 10): the IMU is one more input, and the
estimator is the sliding-window smoother once it is initialised.

Per frame, :meth:`VioStage.process` gets the IMU samples since the previous frame, the tracker's
KLT tracks (ids and undistorted pixels) and the VO keyframe the frame became, if any:

1. static start: while the IMU says the platform stands still from the first sample on, and for
   ``static_init_s``, the static initialisation (gravity direction, gyro bias) starts the smoother
   at rest (:func:`amrvio.imu.static_init.static_init`);
2. otherwise the VO runs as before, and at each of its keyframes the dynamic initialisation
   (:func:`amrvio.estimator.vi_init.initialize_vi`) is tried on the current map's keyframes; its
   report goes into the record; once it is OK the smoother starts at the newest keyframe, in the
   gravity-aligned metric world, with the map's points it sees as landmarks;
3. then every frame's tracks go to :meth:`VioBackend.add_frame`; a frame that is blurred, dropped,
   repeated or lost gets an IMU prediction (``propagate(..., bridged=True)``), which the next
   update corrects, spread over the gap (:meth:`BodyTrack.set`); a frame at
   standstill (the tracks and the IMU both say so, :mod:`amrvio.pipeline.zero_velocity`) adds
   ``v = 0`` to its update, which stops the velocity drifting while the platform stands;
4. a failed consistency check re-initialises the smoother at its own IMU prediction (logged as a
   ``vio_reinit`` event), with its landmarks unless the state jump or the reprojection check
   failed (a scale or bias-drift check only once it has kept failing for
   ``VioStageConfig.reinit_after_s``, :meth:`BodyTrack.restart_due`), and so does a solver
   failure (with the old landmarks, then without); an IMU gap, or ``MAX_SOLVER_FAILURES``
   solver failures in a row, go back to step 2.

:class:`BodyTrack` keeps each frame's body pose, updated while its state stays in the window.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from amrvio.diagnostics.frame import FrameDiagnostics
from amrvio.diagnostics.health import FrameHealth
from amrvio.estimator.initializer import STILL_MRAD, angle_px
from amrvio.estimator.local_mapping import LocalMapping, Segment
from amrvio.estimator.vi_init import (
    ViBiasPrior,
    ViInitConfig,
    ViInitResult,
    ViInitStatus,
    bias_prior_from_static,
    initialize_vi,
    next_window_start,
)
from amrvio.estimator.vio_backend import VioBackend
from amrvio.estimator.vio_types import (
    PriorSigmas,
    VioConfig,
    VioEstimate,
    VioInitialState,
    VisualObservations,
)
from amrvio.imu.propagation import ImuBias, InertialState
from amrvio.imu.static_init import StaticInitConfig, StaticInitResult, static_init
from amrvio.pipeline.imu_log import ImuLog
from amrvio.pipeline.records import BodyTrajectory, PoseStatus
from amrvio.pipeline.vio_blur import blur_gate, bridge_after_tracking
from amrvio.pipeline.vio_report import (
    BodyTrack,
    ImuSetup,
    StaticStart,
    VioFrameInput,
    VioPhase,
    VioReport,
    VioStageConfig,
    VoAnchor,
    vio_input,
)
from amrvio.pipeline.zero_velocity import ZeroVelocityDetector
from amrvio.types.lie import SE3, SO3, Sim3
from amrvio.types.sensors import ImuData

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


@dataclass(frozen=True, slots=True)
class SensorStages:
    """The optional stages of the pipeline: the image diagnostics, and the VIO stage (None without
    an IMU, or with ``--no-imu``)."""

    diagnostics: FrameDiagnostics | None = None
    vio: VioStage | None = None


MAX_SOLVER_FAILURES = 3
"""Consecutive solver failures after which the smoother waits for a new initialisation."""
NO_LANDMARKS = (np.zeros(0, dtype=np.int64), np.zeros((0, 3)))  # a restart without landmarks


class VioStage:
    """Construct with the stage config, the (undistorted) pinhole ``K``, the :class:`ImuSetup`
    (IMU noise, ``T_body_cam``, wheel odometry) and the VO's :class:`LocalMapping` (read for its
    keyframes and points)."""

    def __init__(self, config: VioStageConfig, K: F64, setup: ImuSetup,
                 mapping: LocalMapping, init_config: ViInitConfig | None = None) -> None:
        self.cfg = config
        self.setup = setup
        base = init_config or ViInitConfig()
        self.init_cfg = dataclasses.replace(base, gates=dataclasses.replace(
            base.gates, max_scale_rel_std=config.dynamic_init.max_scale_rel_std,
            max_gravity_std_deg=config.dynamic_init.max_gravity_std_deg,
            max_scale_drift=config.dynamic_init.max_scale_drift))
        self.backend = VioBackend(VioConfig(imu=setup.noise, imu_noise_scale=config.imu_noise_scale,
                                            window_keyframes=config.window_keyframes), K, setup.T_body_cam)
        self.mapping = mapping
        self.imu = ImuLog(config.dynamic_init.max_window_s + 3.0)
        self.vo_keyframes: list[tuple[int, int, int]] = []  # (t_ns, segment, kf id) of one segment
        focal_px = float(np.asarray(K)[0, 0])
        self.start = StaticStart(still_px=angle_px(STILL_MRAD, focal_px))
        self.last_init: ViInitResult | None = None
        self.anchor: VoAnchor | None = None
        self.track = BodyTrack()
        self.still = ZeroVelocityDetector(config.zero_velocity, focal_px)

    @property
    def running(self) -> bool:
        return self.backend.initialised

    def frame_imu(self, t_ns: int, imu: ImuData | None) -> ImuData:
        """The IMU samples for the frame at ``t_ns``: ``imu``, the frame's own (added to the
        log), or without them the log's samples around the frame."""
        if imu is None:
            return self.imu.span(t_ns - 200_000_000, t_ns + 50_000_000)
        self.imu.add(imu)
        return imu

    def camera_rotation(self, t0_ns: int, t1_ns: int, imu: ImuData | None) -> F64 | None:
        """``R_cam1_cam0``, the camera's rotation from ``t0_ns`` to ``t1_ns`` by the gyro less the
        running estimate's bias (``imu``: the frame's samples), for the tracker's KLT prediction;
        None when the log does not cover the interval."""
        self.frame_imu(t1_ns, imu)
        newest = self.backend.newest() if self.running else None
        bias = None if newest is None else np.asarray(newest.bias.gyro_rad_s)
        return self.imu.rotation(t0_ns, t1_ns, self.setup.T_body_cam.R.T, bias)

    def blur_gate(self, image_blurred: bool, health: FrameHealth | None, events: list[str]) -> bool:
        """Whether the frame is too blurred to track (:func:`amrvio.pipeline.vio_blur.blur_gate`)."""
        smear = None if health is None else health.blur.smear_px_pred
        return blur_gate(image_blurred, smear, self.running, self.cfg, events)

    def process(self, index: int, inp: VioFrameInput, events: list[str]) -> VioReport:
        """The frame's report; its body pose goes into :attr:`track`; events are appended."""
        imu = self.frame_imu(inp.t_ns, inp.imu)
        obs = VisualObservations(inp.ids, inp.uv) if inp.usable else VisualObservations.empty()
        zv = self.still.observe(inp.t_ns, inp.ids if inp.usable else None, inp.uv, self.imu, events)
        if not self.running:
            return self._before(index, inp, obs, events)
        if not inp.usable or len(obs) < self.cfg.min_tracks or \
                bridge_after_tracking(inp.smear_px, inp.exposure_known, inp.pnp_posed, self.cfg, events):
            est = self.backend.propagate(inp.t_ns, imu, bridged=True)
            if not est.ok or est.state is None:
                return VioReport(VioPhase.NO_IMU, est, last_init=self.last_init, init_kind=self.track.init_kind)
            self.track.set(index, inp.t_ns, est.state.T_world_body, bridged=True)
            self.track.update(self.backend.window(), index)
            events.append("vio_bridged")
            return VioReport(VioPhase.BRIDGED, est, last_init=self.last_init, init_kind=self.track.init_kind)
        landmarks = self.backend.landmarks()
        sigma_zv = self.cfg.zero_velocity.sigma_m_s
        body_v = (np.zeros(3), sigma_zv) if zv.still and sigma_zv > 0 else self._wheel_velocity(inp.t_ns)
        res = self.backend.add_frame(inp.t_ns, imu, obs, body_v)
        est, pred = res.estimate, res.predicted
        if not est.ok or est.state is None:
            if pred is None:  # the IMU does not cover the frame: back to the VO until a new init
                events.append(f"vio_failed:{est.status.value}")
                self.vo_keyframes.clear()
                return VioReport(VioPhase.NO_IMU, est, last_init=self.last_init, init_kind=self.track.init_kind)
            # the solver failed: restart at the IMU prediction with the landmarks it had; after a
            # second failure in a row without them (they may be what the solver cannot take); a
            # third gives the smoother up until the VO initialises it again (no endless loop)
            self.track.solver_failures += 1
            self.track.consistent = False
            self.track.set(index, inp.t_ns, pred.T_world_body, bridged=True)
            if self.track.solver_failures >= MAX_SOLVER_FAILURES:
                events.append(f"vio_failed:{est.status.value}")
                self.track.solver_failures = 0
                self.vo_keyframes.clear()
                return VioReport(VioPhase.BRIDGED, est, last_init=self.last_init, init_kind=self.track.init_kind)
            events.append(f"vio_reinit:{est.status.value}")
            self._reinit(pred, obs, imu, landmarks if self.track.solver_failures == 1 else NO_LANDMARKS)
            return VioReport(VioPhase.BRIDGED, est, last_init=self.last_init, init_kind=self.track.init_kind)
        self.track.solver_failures = 0
        self.track.consistent = res.checks is None or res.checks.ok
        if res.checks is not None and self.track.restart_due(
                res.checks, self.cfg.reinit_after_s if self.cfg.reinit_on_check_failure else None):
            failed = [c.value for c in res.checks.failed]
            events.append(f"vio_reinit:{'+'.join(failed)}")
            base = res.predicted if res.predicted is not None else est.state
            if any(c.startswith("bias") for c in failed):
                # a bias that ran away would stay: restart from the initialisation's biases
                base = dataclasses.replace(base, bias=self._initial_bias(base.bias))
            # the rejected update gives no pose: neither to this frame nor to the window's frames
            # (it moved them too); the frame is the restarted smoother's first state
            self.track.set(index, inp.t_ns, base.T_world_body)
            # a state jump or landmarks that no longer fit: they are the suspects (kept, they pull
            # the restart the same way); a scale or bias failure keeps them (they hold the scale)
            suspect = "state_jump" in failed or "reprojection" in failed
            restart = self._reinit(base, obs, imu, NO_LANDMARKS if suspect else landmarks)
            return VioReport(VioPhase.VIO, restart, res.keyframe, last_init=self.last_init, checks=res.checks,
                             init_kind=self.track.init_kind, zero_velocity=zv)
        self.track.set(index, inp.t_ns, est.state.T_world_body, predicted=None if pred is None else pred.T_world_body)
        self.track.update(self.backend.window(), index)
        return VioReport(VioPhase.VIO, est, res.keyframe, last_init=self.last_init, checks=res.checks,
                         init_kind=self.track.init_kind, zero_velocity=zv)

    def finish(self, T_world_cam: F64, statuses: list[PoseStatus],
               segments: list[Segment]) -> tuple[BodyTrajectory | None, list[PoseStatus]]:
        """The body trajectory (None when the stage never started) and the final statuses: a
        frame the stage posed is TRACKED (BRIDGED when the IMU alone posed it); before the start,
        a VO pose is put in the VIO world by the dynamic initialisation's scale and gravity."""
        n = len(statuses)
        if not self.track.poses:
            return None, statuses
        out = np.full((n, 4, 4), np.nan)
        new = list(statuses)
        first = min(self.track.poses)
        for i, T in self.track.poses.items():
            out[i] = T
            new[i] = PoseStatus.BRIDGED if i in self.track.bridged else PoseStatus.TRACKED
        a = self.anchor
        T_cam_body = self.setup.T_body_cam.inverse().matrix()
        for i in range(n):
            if i in self.track.poses:
                continue
            if a is None or i > first or statuses[i] is PoseStatus.LOST or not np.all(np.isfinite(T_world_cam[i])):
                new[i] = PoseStatus.LOST
                continue
            # VO world -> the anchor segment's frame -> the VIO world
            to_seg = segments[a.segment].world_from_segment.inverse()
            vio_from_seg = Sim3.from_se3(SE3(SO3(a.R_world_vo), np.zeros(3)), a.scale)
            out[i] = (vio_from_seg @ to_seg).transform_pose_matrix(T_world_cam[i]) @ T_cam_body
        return BodyTrajectory(out, first), new

    # ------------------------------------------------------------------ initialisation
    def _before(self, index: int, inp: VioFrameInput, obs: VisualObservations,
                events: list[str]) -> VioReport:
        static = None
        if not self.start.decided and self.cfg.static_init_s > 0:
            static = self._try_static(inp.t_ns, obs)
            if static is not None and static.ok:
                est = self._start_static(static, inp.t_ns, obs)
                events.append(f"vio_static_init:tilt_std_deg={static.tilt_std_deg:.3f}")
                for i in range(index + 1):  # the platform stood still since the start
                    if i not in self.track.poses and est.state is not None:
                        self.track.poses[i] = est.state.T_world_body.matrix()
                return VioReport(VioPhase.VIO, est, True, static=static, init_kind=self.track.init_kind)
        attempt = None
        if inp.vo_keyframe is not None:
            seg, kf = inp.vo_keyframe
            if self.vo_keyframes and self.vo_keyframes[-1][1] != seg:
                self.vo_keyframes.clear()  # a new map: its scale is another
            self.vo_keyframes.append((inp.t_ns, seg, kf))
            attempt = self._try_dynamic(inp, obs, events)
        if self.running:
            est = self.backend.propagate(inp.t_ns, self.imu.span(inp.t_ns - 10**8, inp.t_ns + 10**8))
            if est.state is not None:
                self.track.set(index, inp.t_ns, est.state.T_world_body)
            return VioReport(VioPhase.VIO, est, True, attempt, static, self.last_init, init_kind=self.track.init_kind)
        return VioReport(VioPhase.VO, None, False, attempt, static, self.last_init)

    def _try_static(self, t_ns: int, obs: VisualObservations) -> StaticInitResult | None:
        """Decide the static start (None: not yet). The IMU still from its first sample for
        ``static_init_s`` and the tracks where they were in the first frame: OK; otherwise
        decided for good (a constant velocity looks still to an IMU, not to the camera)."""
        st = self.start
        if st.ids is None:
            st.ids, st.uv = obs.ids.copy(), obs.uv_px.copy()
        t0 = self.imu.first
        if t0 < 0 or (t_ns - t0) * 1e-9 < self.cfg.static_init_s:
            return None
        st.decided = True
        res = static_init(self.imu.span(t0, t_ns), noise=self.backend.cfg.imu)
        st.result = res
        first_uv = st.uv if st.uv is not None else np.zeros((0, 2))
        common, a, b = np.intersect1d(st.ids, obs.ids, return_indices=True)
        moved = float(np.median(np.linalg.norm(obs.uv_px[b] - first_uv[a], axis=1))) if len(common) >= 10 \
            else float("inf")
        return res if moved <= st.still_px else None

    def _start_static(self, static: StaticInitResult, t_ns: int, obs: VisualObservations) -> VioEstimate:
        R = np.asarray(static.R_world_body)
        up = -np.asarray(static.gravity_body)
        bias = ImuBias(np.asarray(static.gyro_bias_rad_s), up * static.accel_bias_up_m_s2)
        state = InertialState(int(t_ns), SE3(SO3(R), np.zeros(3)), np.zeros(3), bias)
        g_std = np.asarray(static.gyro_bias_std_rad_s if static.gyro_bias_std_rad_s is not None else np.zeros(3))
        # the accelerometer bias across gravity reads as tilt at rest: its prior is the static
        # initialiser's (a factory-calibrated MEMS), along gravity it was measured
        sig = PriorSigmas(rotation_rad=float(np.radians(max(static.tilt_std_deg, 0.05))), position_m=1e-3,
                          velocity_m_s=0.01, gyro_bias_rad_s=float(max(np.max(g_std), 5e-4)),
                          accel_bias_m_s2=StaticInitConfig().accel_bias_sigma_m_s2)
        self.track.init_kind = "static"
        return self.backend.initialise(VioInitialState(state, sig), self.imu.span(t_ns - 10**8, t_ns), obs)

    def _try_dynamic(self, inp: VioFrameInput, obs: VisualObservations, events: list[str]) -> ViInitResult | None:
        kfs = [k for k in self.vo_keyframes if (inp.t_ns - k[0]) * 1e-9 <= self.cfg.dynamic_init.max_window_s]
        self.vo_keyframes = kfs
        if len(kfs) < self.cfg.dynamic_init.min_keyframes:
            return None
        seg_id = kfs[-1][1]
        seg = self.mapping.segments[seg_id]
        kf_map = seg.mapper.map.keyframes
        stamps = np.array([k[0] for k in kfs], dtype=np.int64)
        T_vo_cam = np.stack([np.linalg.inv(kf_map[k[2]].T_cam_world) for k in kfs])
        imu = self.imu.span(int(stamps[0]) - 50_000_000, int(stamps[-1]) + 50_000_000)
        prior = bias_prior_from_static(self.start.result, self.init_cfg) if self.start.result is not None \
            else None
        res = initialize_vi(stamps, T_vo_cam, imu, self.setup.T_body_cam, self.backend.cfg.imu, self.init_cfg, prior)
        self.last_init = res
        scale, use = float(res.scale), res if res.ok else None
        if not res.ok and self._wheel_velocity(inp.t_ns) is not None:
            # the IMU cannot see the scale (constant velocity): the wheels can
            w_scale, w_res = self._wheel_scale(stamps, T_vo_cam, imu, prior)
            if w_res.state is not None and np.isfinite(w_scale):
                scale, use = w_scale, w_res
                events.append(f"vi_init_wheel:scale={scale:.5g}:imu_status={res.status.value}")
        if use is None or use.state is None:
            events.append(f"vi_init_failed:{res.status.value}")
            self.vo_keyframes = kfs[next_window_start(res, len(kfs)):]
            return res
        st = use.state
        s, R_wv = scale, np.asarray(st.R_world_vo)
        T_cam_body = self.setup.T_body_cam.inverse().matrix()
        T_vo_body = T_vo_cam[-1] @ T_cam_body
        T_vo_body[:3, 3] = s * T_vo_cam[-1][:3, 3] + T_vo_cam[-1][:3, :3] @ T_cam_body[:3, 3]
        T_wb = SE3(SO3(R_wv @ T_vo_body[:3, :3]), R_wv @ T_vo_body[:3, 3])
        v_vo = np.asarray(st.velocities_vo)[-1] * (s / float(st.scale))
        state = InertialState(inp.t_ns, T_wb, R_wv @ v_vo,
                              ImuBias(np.asarray(st.gyro_bias_rad_s), np.asarray(st.accel_bias_m_s2)))
        m = seg.mapper.map
        has = m.points_of(obs.ids) if len(obs) else np.zeros(0, dtype=bool)
        ids = obs.ids[has]
        X = (s * (R_wv @ m.xyz[ids].T)).T if len(ids) else np.zeros((0, 3))
        sig = PriorSigmas(velocity_m_s=max(0.05, 3 * s * 0.01), landmark_m=max(0.02, 3 * float(st.scale_std) * 2))
        self.backend.initialise(VioInitialState(state, sig, ids, X), imu.window(inp.t_ns - 10**8, inp.t_ns), obs)
        self.anchor = self.anchor or VoAnchor(seg_id, s, R_wv)
        self.track.init_kind = "dynamic"
        if use is res:
            events.append(f"vi_init_ok:scale={s:.5g}:std={st.scale_std:.3g}")
        return res

    def _initial_bias(self, fallback: ImuBias) -> ImuBias:
        """The biases the running estimate started from: the dynamic initialisation's, or the
        static one's (its gyro bias and the accelerometer bias along gravity), else ``fallback``."""
        init = self.last_init
        if init is not None and init.ok and init.state is not None:
            return ImuBias(np.asarray(init.state.gyro_bias_rad_s), np.asarray(init.state.accel_bias_m_s2))
        st = self.start.result
        if st is not None and st.ok and st.gyro_bias_rad_s is not None and st.gravity_body is not None:
            return ImuBias(np.asarray(st.gyro_bias_rad_s), -np.asarray(st.gravity_body) * st.accel_bias_up_m_s2)
        return fallback

    def _wheel_velocity(self, t_ns: int) -> tuple[F64, float] | None:
        """The wheel odometry's body velocity (forward, 0, 0) at ``t_ns`` and its sigma, if any."""
        wheel, sigma = self.setup.wheel, self.cfg.wheel_sigma_m_s
        if wheel is None or sigma <= 0:
            return None
        t = wheel.stamps_ns
        if len(t) < 2 or not int(t[0]) <= t_ns <= int(t[-1]):
            return None
        v = float(np.interp(float(t_ns), t.astype(np.float64), wheel.v_forward_m_s))
        return np.array([v, 0.0, 0.0]), sigma

    def _wheel_scale(self, stamps: I64, T_vo_cam: F64, imu: ImuData,
                     prior: ViBiasPrior | None) -> tuple[float, ViInitResult]:
        """The scale from the wheels (distance between keyframes over the VO's); the initialiser
        solves gravity, velocities and biases anyway (``solve_degenerate``) with it as the scale's
        prior (relative std: wheel speed sigma / mean speed; the IMU's own is noise here)."""
        wheel = self.setup.wheel
        if wheel is None:
            return float("nan"), ViInitResult(ViInitStatus.TOO_FEW_KEYFRAMES, "no wheel odometry")
        T_cam_body = self.setup.T_body_cam.inverse().matrix()
        p_body = np.einsum("nij,j->ni", T_vo_cam, T_cam_body[:, 3])[:, :3]  # body origin, VO units
        vo = float(np.sum(np.linalg.norm(np.diff(p_body, axis=0), axis=1)))
        metres = wheel.distance_m(int(stamps[0]), int(stamps[-1]))  # the integral is additive
        if not (vo > 0 and metres > 0.2):  # the lever arm parts body and camera paths in turns only
            return float("nan"), ViInitResult(ViInitStatus.INSUFFICIENT_EXCITATION, "the wheels hardly moved")
        scale, speed = metres / vo, metres / ((int(stamps[-1]) - int(stamps[0])) * 1e-9)
        cfg = dataclasses.replace(self.init_cfg, solve_degenerate=True)
        return scale, initialize_vi(stamps, T_vo_cam, imu, self.setup.T_body_cam, self.backend.cfg.imu, cfg, prior,
                                    (scale, scale * (max(self.cfg.wheel_sigma_m_s, 1e-3) / speed)))

    def _reinit(self, base: InertialState, obs: VisualObservations, imu: ImuData,
                landmarks: tuple[I64, F64]) -> VioEstimate:
        """Restart the smoother at ``base`` with loose priors, keeping the landmarks it had before
        the failed update (they hold the scale) with a loose prior too; returns its first estimate."""
        sig = PriorSigmas(rotation_rad=0.02, position_m=0.02, velocity_m_s=0.2, gyro_bias_rad_s=0.01,
                          accel_bias_m_s2=0.2, landmark_m=0.1)
        ids, X = landmarks
        self.track.init_kind = "reinit"
        return self.backend.initialise(VioInitialState(base, sig, ids, X), imu, obs)


__all__ = ["BodyTrack", "ImuSetup", "SensorStages", "VioFrameInput", "VioStage", "VioStageConfig", "VoAnchor",
           "vio_input"]
