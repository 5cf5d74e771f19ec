"""Sliding-window visual-inertial odometry on GTSAM (issue 10, points 3 and 6).

One stage with a narrow interface, fed by the pipeline:

- ``initialise(VioInitialState, imu, observations)``: the VI initialiser's state (gravity-aligned
  world, metric) becomes the first keyframe, with priors of its uncertainty;
- ``add_frame(t_ns, imu, observations) -> FrameResult``: the IMU since the previous frame is
  preintegrated into a ``CombinedImuFactor`` (bias random walk included), the observations become
  Huber-robust projection factors on landmarks (triangulated from the window's poses once their
  rays have parallax), and an ``IncrementalFixedLagSmoother`` (iSAM2) updates the window. The
  frame becomes a keyframe when it moved enough against the last keyframe (or sees too few
  landmarks); otherwise it stays only until the next frame arrives, and is then dropped with its
  visual factors (VINS-Mono's policy: standing still or turning on the spot does not push the
  keyframes, and their landmarks, out of the window). Old keyframes are marginalised with the
  landmarks they saw first, so the marginal prior links frame states only
  (:mod:`amrvio.estimator.vio_landmarks`). iSAM2 then holds the marginal's variables at their
  linearisation points; once one has moved far from its point, the window goes into a new
  smoother at the current estimate (:mod:`amrvio.estimator.vio_relinearise`).
  The result carries the consistency checks of :mod:`amrvio.estimator.vio_checks`;
- ``propagate(t_ns, imu, bridged) -> VioEstimate``: the IMU prediction from the newest frame for
  a frame not given to ``add_frame``, or one that was dropped (blur) or lost (``bridged=True``),
  with its growing uncertainty.

The pipeline may give every frame to ``add_frame`` or only some (its own keyframes); IMU windows
may overlap and overshoot (``amrvio.imu.propagation.ImuBuffer``).
"""

from __future__ import annotations

import time
from collections import deque
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from amrvio.errors import ShapeError
from amrvio.estimator.vio_checks import KeyframeCheckInput, check_keyframe
from amrvio.estimator.vio_graph import (
    EXPIRED,
    WindowFrame,
    add_priors,
    age_noise,
    live_slots,
    make_camera,
    make_smoother,
    marginal_covariance,
    prior_sigmas_15,
    smoother_params,
    smoother_update,
    state_keys,
    sym,
)
from amrvio.estimator.vio_landmarks import LandmarkTracks, project_px, range_ratio_within
from amrvio.estimator.vio_relinearise import REBUILD_THRESHOLD, fixed_due, rebuild
from amrvio.estimator.vio_triangulate import keyframe_due, triangulate_pending
from amrvio.estimator.vio_types import (
    EstimateKind,
    FrameResult,
    VioConfig,
    VioEstimate,
    VioInitialState,
    VioStatus,
    VisualObservations,
    VisualStats,
)
from amrvio.imu.propagation import (
    ImuBuffer,
    InertialState,
    Preintegrator,
    from_gtsam_bias,
    from_gtsam_pose,
    preintegration_params,
    to_gtsam_bias,
    to_gtsam_pose,
    world_position_velocity_sigma,
)
from amrvio.types.lie import SE3
from amrvio.types.sensors import ImuData

if TYPE_CHECKING:
    import gtsam

F64 = NDArray[np.float64]

#: frames kept for the consistency checks (they look back ``checks.window_s``)
HISTORY = 512


class VioBackend:
    """The sliding-window smoother (see the module docstring). ``K``: the pinhole camera matrix of
    the (undistorted) observations; ``T_body_cam``: the camera pose in the body (IMU) frame."""

    def __init__(self, config: VioConfig, K: ArrayLike, T_body_cam: SE3) -> None:
        self.cfg = config
        self._cam = make_camera(K, T_body_cam, config.visual)
        self._buffer = ImuBuffer(config.max_imu_gap_s)
        self._pre = Preintegrator(preintegration_params(config.imu_model(), config.gravity_m_s2), self._buffer)
        self._smoother: gtsam.IncrementalFixedLagSmoother | None = None
        self._values: gtsam.Values | None = None
        self._tracks = LandmarkTracks()
        self._window: list[WindowFrame] = []
        self._last: tuple[InertialState, F64] | None = None  # newest frame's state and 15x15 covariance
        self._history: deque[KeyframeCheckInput] = deque(maxlen=HISTORY)
        self._seed_sigma_m = 0.05  # prior sigma of the initialiser's landmarks (VioInitialState.sigmas)

    @property
    def initialised(self) -> bool:
        return self._last is not None

    @property
    def factor_slots(self) -> tuple[int, int]:
        """(slots, factors) of the smoother's factor list: the slots stay near the factors."""
        graph = self._smoother.getFactors() if self._smoother is not None else None
        return (0, 0) if graph is None else (int(graph.size()), int(graph.nrFactors()))

    def initialise(self, init: VioInitialState, imu: ImuData | None = None,
                   observations: VisualObservations | None = None) -> VioEstimate:
        """Start (or restart) the window at ``init.state``; ``observations``: what the first
        keyframe sees (they become landmarks when later keyframes see them too)."""
        import gtsam

        s = init.state
        if imu is not None:
            self._buffer.add(imu)
        self._smoother = make_smoother(self.cfg.window_keyframes)
        seeds = {int(i): X for i, X in zip(init.landmark_ids.tolist(), init.landmarks_world, strict=True)}
        self._tracks = LandmarkTracks(seeds=seeds)
        self._history.clear()
        self._seed_sigma_m = init.sigmas.landmark_m
        graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        add_priors(graph, values, 0, s, init.sigmas)
        stamps = dict.fromkeys(state_keys(0), 0.0)
        obs = VisualObservations.empty() if observations is None else observations
        for lm_id, uv in zip(obs.ids.tolist(), obs.uv_px, strict=True):
            self._tracks.observe_pending(lm_id, 0, uv)
        triangulate_pending(self._tracks, obs, 0, {0: s.T_world_body @ self._cam.T_body_cam}, {0: 0}, self._cam,
                            self.cfg.visual, graph, values, stamps, [], self._seed_sigma_m)
        smoother_update(self._smoother, graph, values, stamps, [], 0)
        self._values = self._smoother.calculateEstimate()
        self._window = [WindowFrame(0, s.t_ns, 0, True)]
        cov = np.diag(prior_sigmas_15(init.sigmas) ** 2)
        self._last = (s, cov)
        self._pre.reset(s.t_ns, s.bias)
        p_sig, v_sig = world_position_velocity_sigma(s, cov)
        return VioEstimate(s.t_ns, EstimateKind.INITIAL, VioStatus.OK, s, p_sig, v_sig)

    def propagate(self, t_ns: int, imu: ImuData, bridged: bool = False) -> VioEstimate:
        """The IMU prediction at ``t_ns`` from the newest frame (biases held), with per-axis
        sigmas; ``bridged`` marks a frame that was dropped or lost. ``imu`` may overlap what was
        given before; it must reach ``t_ns``."""
        kind = EstimateKind.BRIDGED if bridged else EstimateKind.PROPAGATED
        if self._last is None:
            return VioEstimate(int(t_ns), kind, VioStatus.NOT_INITIALISED)
        self._buffer.add(imu)
        last, last_cov = self._last
        since = (int(t_ns) - last.t_ns) * 1e-9
        if not self._pre.advance(int(t_ns)).ok:
            return VioEstimate(int(t_ns), kind, VioStatus.IMU_GAP, since_smoothed_s=since)
        state, cov = self._pre.predict(last, last_cov)
        p_sig, v_sig = world_position_velocity_sigma(state, cov)
        return VioEstimate(int(t_ns), kind, VioStatus.OK, state, p_sig, v_sig, since)

    def add_frame(self, t_ns: int, imu: ImuData, observations: VisualObservations,
                  body_velocity: tuple[F64, float] | None = None) -> FrameResult:
        """Insert the frame at ``t_ns`` and update the window (see the module docstring).
        ``body_velocity``: a measured velocity of the body in its own frame (3,) m/s and its
        standard deviation per axis (wheel odometry: forward speed, no sideways or vertical
        motion); it becomes a prior on the world velocity through the IMU-predicted attitude."""
        import gtsam

        t0, t_ns, nobs = time.perf_counter(), int(t_ns), len(observations)
        if self._last is None or self._smoother is None:
            est = VioEstimate(t_ns, EstimateKind.SMOOTHED, VioStatus.NOT_INITIALISED)
            return FrameResult(est, False, None, VisualStats(nobs), None, time.perf_counter() - t0)
        last, last_cov = self._last
        if t_ns <= last.t_ns:
            raise ShapeError(f"frame times must increase: {t_ns} ns after {last.t_ns} ns")
        self._buffer.add(imu)
        if not self._pre.advance(t_ns).ok:
            since = (t_ns - last.t_ns) * 1e-9
            est = VioEstimate(t_ns, EstimateKind.SMOOTHED, VioStatus.IMU_GAP, since_smoothed_s=since)
            self._drop_state()
            return FrameResult(est, False, None, VisualStats(nobs), None, time.perf_counter() - t0)
        predicted, pred_cov = self._pre.predict(last, last_cov)
        disp_cov = last_cov.copy()
        disp_cov[3:6, :] = disp_cov[:, 3:6] = 0.0  # the previous position is not part of a displacement
        disp_p_sig, _ = world_position_velocity_sigma(predicted, self._pre.predict(last, disp_cov)[1])
        disp_sig = float(np.linalg.norm(disp_p_sig))
        prev = self._window[-1]
        last_kf = next(f for f in reversed(self._window) if f.keyframe)
        k, ordinal = prev.index + 1, last_kf.ordinal + 1
        first_kf = self._first_kept(ordinal)
        self._tracks.forget_before(first_kf)  # what this update marginalises
        T_wc_pred = predicted.T_world_body @ self._cam.T_body_cam
        seen, n_gated = self._gate(observations, T_wc_pred)
        is_kf = self._is_keyframe(seen, T_wc_pred, last_kf)
        graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        X, V, B = state_keys(k)
        Xp, Vp, Bp = state_keys(prev.index)
        graph.add(gtsam.CombinedImuFactor(Xp, Vp, X, V, Bp, B, self._pre.pim))
        values.insert(X, to_gtsam_pose(predicted.T_world_body))
        values.insert(V, np.asarray(predicted.v_world_m_s))
        values.insert(B, to_gtsam_bias(last.bias))
        if body_velocity is not None:
            v_body, v_sigma = body_velocity
            v_world = predicted.T_world_body.R @ np.asarray(v_body, dtype=np.float64)
            graph.add(gtsam.PriorFactorVector(V, v_world, gtsam.noiseModel.Isotropic.Sigma(3, float(v_sigma))))
        stamps: dict[int, float] = dict.fromkeys((X, V, B), float(ordinal))
        frame = WindowFrame(k, t_ns, ordinal, is_kf)
        removed: list[int] = []
        if not prev.keyframe:  # the previous frame was kept only until this one: drop it
            stamps.update(dict.fromkeys((Xp, Vp, Bp), EXPIRED))
            removed = live_slots(self._smoother, prev.slots, prev.factors)
        born = {lm.key: lm.first_keyframe for lm in self._tracks.active.values()}
        first, used = graph.size(), list(seen)
        factors = [self._cam.factor(uv, k, key, age_noise(self.cfg.visual, k - born.get(key, k))) for key, uv in used]
        for f in factors:
            graph.add(f)
        n_new = 0
        if is_kf:
            for lm_id, uv in zip(observations.ids.tolist(), observations.uv_px, strict=True):
                if lm_id not in self._tracks.active:
                    self._tracks.observe_pending(lm_id, k, uv)
            cams = {f.index: self._kf_camera(f.index) for f in self._window if f.keyframe and f.index >= first_kf}
            cams[k] = T_wc_pred
            ordinals = {f.index: f.ordinal for f in self._window}
            ordinals[k] = ordinal
            n_new = triangulate_pending(self._tracks, observations, k, cams, ordinals, self._cam, self.cfg.visual,
                                        graph, values, stamps, used, self._seed_sigma_m)
        try:
            slots = smoother_update(self._smoother, graph, values, stamps, removed, k)
            for _ in range(self.cfg.iterations - 1):
                self._smoother.update()
            if fixed_due(self._smoother, REBUILD_THRESHOLD):  # vio_relinearise: iSAM2 fixed it far off
                self._smoother, moved = rebuild(self._smoother, smoother_params(), k)
                slots = [moved.get(s, -1) for s in slots]  # the prior of z (smoother_update) is gone
            self._values = self._smoother.calculateEstimate()
            cov = marginal_covariance(self._smoother, self._values, k)
        except RuntimeError:  # gtsam: indeterminant linear system
            est = VioEstimate(t_ns, EstimateKind.SMOOTHED, VioStatus.SOLVER_FAILED)
            self._drop_state()
            return FrameResult(est, is_kf, predicted, VisualStats(nobs, len(used), n_gated, n_new), None,
                               time.perf_counter() - t0)
        if not is_kf:
            frame.slots, frame.factors = slots[first:first + len(factors)], factors
        self._window = [f for f in self._window if f.ordinal >= ordinal - (self.cfg.window_keyframes - 1)
                        and (f.keyframe or f is not prev)] + [frame]
        state = self._smoothed(k, t_ns)
        self._last = (state, cov)
        self._pre.reset(t_ns, state.bias)
        self._buffer.forget_before(t_ns)
        rms = self._rms_px(state, used)
        pp_sig, pv_sig = world_position_velocity_sigma(predicted, pred_cov)
        bias_sig = np.sqrt(np.maximum(np.diag(cov)[9:], 0.0))
        self._history.append(KeyframeCheckInput(predicted, pp_sig, pv_sig, disp_sig, state, bias_sig[3:], bias_sig[:3],
                                                rms))
        while (t_ns - self._history[0].optimised.t_ns) * 1e-9 > self.cfg.checks.window_s + 1.0:
            self._history.popleft()
        report = check_keyframe(self._history, self.cfg.imu_model(), self.cfg.checks)
        p_sig, v_sig = world_position_velocity_sigma(state, cov)
        est = VioEstimate(t_ns, EstimateKind.SMOOTHED, VioStatus.OK, state, p_sig, v_sig)
        stats = VisualStats(nobs, len(used), n_gated, n_new, len(self._tracks.active), rms)
        return FrameResult(est, is_kf, predicted, stats, report, time.perf_counter() - t0)

    def window(self) -> tuple[tuple[InertialState, bool], ...]:
        """The smoothed states of the frames in the window, oldest first, each with whether it is
        a keyframe (a state keeps improving after its own frame's update)."""
        if self._values is None:
            return ()
        return tuple((self._smoothed(f.index, f.t_ns), f.keyframe) for f in self._window)

    def newest(self) -> InertialState | None:
        """The smoothed state of the window's newest frame (``window()[-1]``, without reading the
        others); None before the first initialisation."""
        if self._values is None or not self._window:
            return None
        f = self._window[-1]
        return self._smoothed(f.index, f.t_ns)

    def _smoothed(self, k: int, t_ns: int) -> InertialState:
        """The current estimate of frame ``k``'s state (its pose, velocity and biases)."""
        vals = self._estimate()
        X, V, B = state_keys(k)
        return InertialState(t_ns, from_gtsam_pose(vals.atPose3(X)), np.asarray(vals.atVector(V)),
                             from_gtsam_bias(vals.atConstantBias(B)))

    def landmarks(self) -> tuple[NDArray[np.int64], F64]:
        """The front-end ids (L,) and current world positions (L, 3) of the window's landmarks
        (for a re-initialisation that keeps them)."""
        if self._values is None or not self._tracks.active:
            return np.zeros(0, dtype=np.int64), np.zeros((0, 3))
        ids = np.array(sorted(self._tracks.active), dtype=np.int64)
        X = np.array([self._landmark(self._tracks.active[int(i)].key) for i in ids])
        return ids, X.reshape(-1, 3)

    def landmarks_agreeing(self, T_world_cam: SE3, ids: NDArray[np.int64], uv_px: F64) -> F64:
        """(L', 3) world positions of the window's landmarks, less those that a track (front-end
        ``ids`` (N,) seen at ``uv_px`` (N, 2) by a camera at ``T_world_cam``) puts further than
        ``visual.gate_px`` from their projection: the smoother would not use that observation,
        so the landmark or its track is wrong (issue 13: one such landmark at 40 % of its true
        depth made a frame's predicted smear 18 % high)."""
        lm_ids, X = self.landmarks()
        seen = {int(i): k for k, i in enumerate(np.asarray(ids).tolist())}
        rows = [j for j, i in enumerate(lm_ids.tolist()) if i in seen]
        if not rows:
            return X
        uv_pred, _ = project_px(self._cam.K, T_world_cam, X[rows])
        err = np.linalg.norm(uv_pred - np.asarray(uv_px)[[seen[int(lm_ids[j])] for j in rows]], axis=1)
        keep = np.ones(len(X), dtype=bool)
        keep[np.asarray(rows)[~(err <= self.cfg.visual.gate_px)]] = False
        return X[keep]

    # ------------------------------------------------------------------ helpers

    def _drop_state(self) -> None:
        """After a failure: nothing to propagate from until ``initialise`` is called again."""
        self._last = self._smoother = self._values = None
        self._tracks = LandmarkTracks()
        self._window = []
        self._history.clear()

    def _first_kept(self, ordinal: int) -> int:
        """Index of the oldest frame that stays in the window when the newest has ``ordinal``."""
        lo = ordinal - (self.cfg.window_keyframes - 1)
        kept = [f.index for f in self._window if f.keyframe and f.ordinal >= lo]
        return min(kept, default=self._window[-1].index + 1)

    def _estimate(self) -> gtsam.Values:
        if self._values is None:
            raise RuntimeError("VioBackend: no estimate before initialise")  # a bug, not bad input
        return self._values

    def _landmark(self, key: int) -> F64:
        return np.asarray(self._estimate().atPoint3(sym("l", key)))

    def _kf_camera(self, i: int) -> SE3:
        P = from_gtsam_pose(self._estimate().atPose3(sym("x", i)))
        return P @ self._cam.T_body_cam

    def _gate(self, obs: VisualObservations, T_wc_pred: SE3) -> tuple[list[tuple[int, F64]], int]:
        """The (landmark key, uv) of observations of active landmarks within the gate of their
        prediction and within ``max_log_scale`` of their distance from their first keyframe, and
        how many were gated out. A landmark beyond that distance ratio ends here
        (``LandmarkTracks.retire``)."""
        vis, active = self.cfg.visual, self._tracks.active
        rows = [(i, active[lm_id]) for i, lm_id in enumerate(obs.ids.tolist()) if lm_id in active]
        if not rows:
            return [], 0
        Xw = np.array([self._landmark(lm.key) for _, lm in rows])
        uv_obs = obs.uv_px[[i for i, _ in rows]]
        uv_pred, z = project_px(self._cam.K, T_wc_pred, Xw)
        err = np.linalg.norm(uv_pred - uv_obs, axis=1)
        ok = (z > vis.min_depth_m) & (err <= vis.gate_px)
        if vis.max_log_scale > 0:
            # the track outlived its landmark: the front-end id starts a new one (pending, then
            # triangulated again from the views that follow); the old one keeps its views
            centres = {f: self._kf_camera(f).t for f in {lm.first_keyframe for _, lm in rows}}
            first = np.array([centres[lm.first_keyframe] for _, lm in rows])
            beyond = ok & ~range_ratio_within(Xw, first, T_wc_pred.t, vis.max_log_scale)
            self._tracks.retire([int(obs.ids[rows[j][0]]) for j in np.flatnonzero(beyond).tolist()])
            ok &= ~beyond
        return [(rows[j][1].key, uv_obs[j]) for j in np.flatnonzero(ok).tolist()], int(np.count_nonzero(~ok))

    def _is_keyframe(self, seen: list[tuple[int, F64]], T_wc_pred: SE3, last_kf: WindowFrame) -> bool:
        Xw = np.array([self._landmark(key) for key, _ in seen]).reshape(-1, 3)
        if len(Xw):
            self._tracks.typical_depth_m = float(np.median(np.linalg.norm(Xw - T_wc_pred.t, axis=1)))
        return keyframe_due(Xw, self._kf_camera(last_kf.index).t, T_wc_pred.t, self._tracks.typical_depth_m,
                            self.cfg.visual)

    def _rms_px(self, state: InertialState, used: list[tuple[int, F64]]) -> float | None:
        """RMS pixel distance of this frame's used observations to their optimised projection."""
        if not used:
            return None
        Xw = np.array([self._landmark(key) for key, _ in used])
        uv_obs = np.array([uv for _, uv in used])
        uv, _ = project_px(self._cam.K, state.T_world_body @ self._cam.T_body_cam, Xw)
        return float(np.sqrt(np.mean(np.sum((uv - uv_obs) ** 2, axis=1))))


__all__ = ["VioBackend"]
