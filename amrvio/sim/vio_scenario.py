"""Synthetic VIO scenarios for testing and timing the back-end without images: a simulator motion
(exact kinematics), its IMU (amrvio.sim.imu_synth, optionally noisy with bias random walks), and
landmark observations made by projecting random 3-D points on the walls, floor and ceiling of a
box around the path with the ground-truth camera poses (EuRoC cam0 intrinsics, 752 x 480), plus
pixel noise. ``run_frames`` feeds :class:`amrvio.estimator.vio_backend.VioBackend` and keeps the
ground truth next to each result."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from amrvio.estimator.vio_backend import VioBackend
from amrvio.estimator.vio_types import FrameResult, VioConfig, VioInitialState, VisualObservations
from amrvio.geometry.align import umeyama
from amrvio.imu.propagation import ImuBias, InertialState
from amrvio.sim.imu_synth import SyntheticImu, synthesize_imu
from amrvio.sim.kinematics import Motion
from amrvio.sim.motion import default_T_body_cam, make_motion
from amrvio.types.lie import SE3, SO3
from amrvio.types.sensors import ImuData, ImuNoise

F64 = NDArray[np.float64]

#: the scenario's t = 0 (a recording does not start at 0 ns)
START_NS = 1_000_000_000_000
#: EuRoC cam0's pinhole intrinsics and image size
K_EUROC = np.array([[458.654, 0.0, 367.215], [0.0, 457.296, 248.375], [0.0, 0.0, 1.0]])
SIZE_WH = (752, 480)


def box_points(lo: F64, hi: F64, n: int, rng: np.random.Generator) -> F64:
    """``n`` points uniformly on the six faces of the box [lo, hi] (area-weighted)."""
    ext = hi - lo
    areas = np.array([ext[1] * ext[2], ext[1] * ext[2], ext[0] * ext[2], ext[0] * ext[2],
                      ext[0] * ext[1], ext[0] * ext[1]])
    face = rng.choice(6, size=n, p=areas / areas.sum())
    P = lo + rng.uniform(size=(n, 3)) * ext
    axis = face // 2
    P[np.arange(n), axis] = np.where(face % 2 == 0, lo[axis], hi[axis])
    return P


def observe_points(T_world_cam: SE3, points: F64, rng: np.random.Generator, pixel_sigma: float = 0.5,
                   max_obs: int = 150) -> VisualObservations:
    """The points (P, 3) that a camera at ``T_world_cam`` (K_EUROC, 752 x 480, 5 px border) sees
    0.3-30 m ahead, ids = row numbers, the ``max_obs`` lowest ids (so tracks persist), with
    Gaussian pixel noise of ``pixel_sigma``."""
    pc = (points - T_world_cam.t) @ T_world_cam.R
    z = pc[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = K_EUROC[0, 0] * pc[:, 0] / z + K_EUROC[0, 2]
        v = K_EUROC[1, 1] * pc[:, 1] / z + K_EUROC[1, 2]
    vis = (z > 0.3) & (z < 30.0) & (u > 5) & (u < SIZE_WH[0] - 5) & (v > 5) & (v < SIZE_WH[1] - 5)
    ids = np.flatnonzero(vis)[:max_obs]
    uv = np.stack([u[ids], v[ids]], axis=1) + rng.normal(0.0, pixel_sigma, (ids.size, 2))
    return VisualObservations(ids, uv)


@dataclass(frozen=True, slots=True, eq=False)
class Scenario:
    """A motion, its IMU (with the true biases), the landmarks (P, 3), the camera mount, the
    random generator of the pixel noise (advanced by every ``observe``), the pixel noise sigma
    and the most landmarks one frame observes."""

    motion: Motion
    syn: SyntheticImu
    points: F64
    T_body_cam: SE3
    rng: np.random.Generator
    pixel_sigma: float
    max_obs: int = 150

    def t_ns(self, t_s: float) -> int:
        """The stamp of scenario time ``t_s``."""
        return START_NS + int(round(t_s * 1e9))

    def true_state(self, t_s: float) -> InertialState:
        """Pose, velocity and the IMU's true biases (at the nearest IMU sample) at ``t_s``."""
        st = self.motion.states(np.array([t_s]))
        i = int(np.argmin(np.abs(self.syn.t_s - t_s)))
        bias = ImuBias(self.syn.gyro_bias[i], self.syn.accel_bias[i])
        return InertialState(self.t_ns(t_s), SE3(SO3.from_matrix(st.R_world_body[0]), st.p_world[0]),
                             st.v_world[0], bias)

    def imu_between(self, t0_s: float, t1_s: float, margin_s: float = 0.01) -> ImuData:
        """The IMU samples in [t0 - margin, t1 + margin]."""
        return self.syn.imu.window(self.t_ns(t0_s - margin_s), self.t_ns(t1_s + margin_s))

    def observe(self, t_s: float) -> VisualObservations:
        """Noisy pixels of the points the camera sees at ``t_s`` (see :func:`observe_points`)."""
        T_wc = self.true_state(t_s).T_world_body @ self.T_body_cam
        return observe_points(T_wc, self.points, self.rng, self.pixel_sigma, self.max_obs)

    def initial(self, t_s: float = 0.0, seed_sigma_m: float | None = None) -> VioInitialState:
        """The true state at ``t_s``; with ``seed_sigma_m``, also the points seen at ``t_s`` with
        that much noise per coordinate (what a VI initialiser hands over with its map)."""
        if seed_sigma_m is None:
            return VioInitialState(self.true_state(t_s))
        ids = self.observe(t_s).ids
        noisy = self.points[ids] + self.rng.normal(0.0, seed_sigma_m, (ids.size, 3))
        return VioInitialState(self.true_state(t_s), landmark_ids=ids, landmarks_world=noisy)


def make_scenario(kind: str, duration_s: float, seed: int = 0, noise: ImuNoise | None = None,
                  pixel_sigma: float = 0.5, n_points: int = 3000,
                  gyro_bias: tuple[float, float, float] = (0.0, 0.0, 0.0),
                  accel_bias: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> Scenario:
    """Motion ``kind`` (amrvio.sim.motion.make_motion) for ``duration_s``, a 200 Hz IMU (exact
    when ``noise`` is None, else with its white noise and bias walks from the given initial
    biases), ``n_points`` landmarks on a box 4 m wider than the path on each side, 0-3 m high,
    and the default camera mount."""
    rng = np.random.default_rng(seed)
    motion = make_motion(kind, duration_s, seed=seed)
    syn = synthesize_imu(motion, 200.0, noise, rng if noise is not None else None, START_NS,
                         gyro_bias, accel_bias)
    p = motion.states(np.linspace(0.0, duration_s, 200)).p_world
    lo = np.array([p[:, 0].min() - 4.0, p[:, 1].min() - 4.0, 0.0])
    hi = np.array([p[:, 0].max() + 4.0, p[:, 1].max() + 4.0, 3.0])
    return Scenario(motion, syn, box_points(lo, hi, n_points, rng), default_T_body_cam(), rng, pixel_sigma)


@dataclass(frozen=True, slots=True, eq=False)
class RunLog:
    """What a run gave: per frame the time (s), the result and the ground truth."""

    t_s: tuple[float, ...]
    results: tuple[FrameResult, ...]
    truth: tuple[InertialState, ...]

    @property
    def states(self) -> list[InertialState]:
        """The estimated states; a frame without one (a failed update) is an error here."""
        out = []
        for t, r in zip(self.t_s, self.results, strict=True):
            if r.estimate.state is None:
                raise RuntimeError(f"frame at {t:.2f} s has no state: {r.estimate.status.value}")
            out.append(r.estimate.state)
        return out

    def position_errors_m(self) -> F64:
        """(N,) distance of each estimated position to the truth."""
        return np.array([np.linalg.norm(e.T_world_body.t - g.T_world_body.t)
                         for e, g in zip(self.states, self.truth, strict=True)])

    def se3_ate_m(self) -> float:
        """RMS position error after the best rigid alignment (Umeyama, no scale)."""
        est = np.array([s.T_world_body.t for s in self.states])
        gt = np.array([s.T_world_body.t for s in self.truth])
        S = umeyama(est, gt, with_scale=False)
        return float(np.sqrt(np.mean(np.sum((S.act(est) - gt) ** 2, axis=1))))

    def failed_checks(self) -> list[tuple[float, str]]:
        """(time, summary) of every frame whose consistency checks failed."""
        return [(t, r.checks.summary()) for t, r in zip(self.t_s, self.results, strict=True)
                if r.checks is not None and not r.checks.ok]


def run_frames(sc: Scenario, backend: VioBackend, t0_s: float, t1_s: float, dt_s: float = 0.1,
               observe: Callable[[float], VisualObservations] | None = None) -> RunLog:
    """``add_frame`` every ``dt_s`` in (t0, t1], with the IMU since the previous frame (10 ms
    margins, as amrvio.imu.window gives it)."""
    see = sc.observe if observe is None else observe
    n = int(round((t1_s - t0_s) / dt_s))
    times = [t0_s + i * dt_s for i in range(1, n + 1)]
    results = [backend.add_frame(sc.t_ns(t), sc.imu_between(t - dt_s, t), see(t)) for t in times]
    return RunLog(tuple(times), tuple(results), tuple(sc.true_state(t) for t in times))


def start(sc: Scenario, t0_s: float = 0.0, seed_sigma_m: float | None = 0.02, config: VioConfig | None = None,
          init: VioInitialState | None = None) -> VioBackend:
    """A back-end initialised at ``t0_s`` with the true state (and the landmarks seen there, with
    ``seed_sigma_m`` noise; None: none), or with ``init``."""
    backend = VioBackend(VioConfig() if config is None else config, K_EUROC, sc.T_body_cam)
    est = backend.initialise(sc.initial(t0_s, seed_sigma_m) if init is None else init,
                             sc.imu_between(t0_s, t0_s + 0.1), sc.observe(t0_s))
    if not est.ok:
        raise RuntimeError(f"initialise failed: {est.status.value}")
    return backend


__all__ = ["K_EUROC", "SIZE_WH", "START_NS", "RunLog", "Scenario", "box_points", "make_scenario", "observe_points",
           "run_frames", "start"]
