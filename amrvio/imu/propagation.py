"""IMU preintegration between keyframes and propagation of the inertial state, on GTSAM.

Conventions: world frame gravity-aligned, z up, gravity ``(0, 0, -g)``; body frame = IMU frame;
gyro in rad/s and specific force in m/s^2, both in the body frame; a bias is subtracted from the
reading (``omega = gyro - b_g``, ``f = accel - b_a``). GTSAM's ``PreintegratedCombinedMeasurements``
(Forster et al. 2017, "On-Manifold Preintegration", eqs. 33-38; the combined form also carries
the bias random walk) holds the preintegrated deltas and their 15x15 covariance.

Samples reach the estimator in windows that overlap and overshoot the frame (``amrvio.imu.window``
adds margins), so :class:`ImuBuffer` keeps every sample once, in time order, and integrates
exactly between two instants that need not be sample stamps: each piece between consecutive
break points (the two instants and the samples between them) uses the reading linearly
interpolated at the middle of the piece (midpoint rule, second order for smooth motion).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from amrvio.errors import ShapeError
from amrvio.types.lie import SE3, SO3, so3_exp
from amrvio.types.sensors import ImuData, ImuNoise

if TYPE_CHECKING:
    import gtsam

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

#: variance (m^2/s^2 per s) of the integration error GTSAM adds to the position (its examples use 1e-8)
INTEGRATION_VARIANCE = 1e-8


def _vec3(x: ArrayLike, name: str) -> F64:
    v = np.array(x, dtype=np.float64)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ShapeError(f"{name} must be a finite (3,) vector, got shape {v.shape}")
    v.setflags(write=False)
    return v


@dataclass(frozen=True, slots=True, eq=False)
class ImuBias:
    """Gyro (rad/s) and accelerometer (m/s^2) biases, body frame: ``omega = gyro - gyro_rad_s``."""

    gyro_rad_s: F64
    accel_m_s2: F64

    def __post_init__(self) -> None:
        object.__setattr__(self, "gyro_rad_s", _vec3(self.gyro_rad_s, "gyro bias"))
        object.__setattr__(self, "accel_m_s2", _vec3(self.accel_m_s2, "accel bias"))

    @staticmethod
    def zero() -> ImuBias:
        return ImuBias(np.zeros(3), np.zeros(3))


@dataclass(frozen=True, slots=True, eq=False)
class InertialState:
    """The navigation state at ``t_ns``: pose of the body (IMU) frame in the world, its velocity
    in the world frame (m/s) and the IMU biases."""

    t_ns: int
    T_world_body: SE3
    v_world_m_s: F64
    bias: ImuBias

    def __post_init__(self) -> None:
        object.__setattr__(self, "v_world_m_s", _vec3(self.v_world_m_s, "velocity"))


def preintegration_params(noise: ImuNoise, gravity_m_s2: float = 9.81) -> gtsam.PreintegrationCombinedParams:
    """GTSAM ``PreintegrationCombinedParams`` from the IMU's continuous-time noise densities.

    GTSAM takes the continuous-time covariances (density squared) and scales them by the sample
    interval itself, so these are exactly the Kalibr/EuRoC numbers squared.
    """
    import gtsam

    if not (np.isfinite(gravity_m_s2) and gravity_m_s2 > 0):
        raise ShapeError(f"gravity must be a positive number of m/s^2, got {gravity_m_s2}")
    p = gtsam.PreintegrationCombinedParams.MakeSharedU(float(gravity_m_s2))
    eye = np.eye(3)
    p.setGyroscopeCovariance(eye * noise.gyro_noise_density**2)
    p.setAccelerometerCovariance(eye * noise.accel_noise_density**2)
    p.setIntegrationCovariance(eye * INTEGRATION_VARIANCE)
    p.setBiasOmegaCovariance(eye * noise.gyro_random_walk**2)
    p.setBiasAccCovariance(eye * noise.accel_random_walk**2)
    return p


def to_gtsam_bias(bias: ImuBias) -> gtsam.imuBias.ConstantBias:
    import gtsam

    return gtsam.imuBias.ConstantBias(np.asarray(bias.accel_m_s2), np.asarray(bias.gyro_rad_s))


def from_gtsam_bias(b: gtsam.imuBias.ConstantBias) -> ImuBias:
    return ImuBias(np.asarray(b.gyroscope()), np.asarray(b.accelerometer()))


def to_gtsam_pose(T: SE3) -> gtsam.Pose3:
    import gtsam

    return gtsam.Pose3(gtsam.Rot3(np.asarray(T.R)), np.asarray(T.t))


def from_gtsam_pose(P: gtsam.Pose3) -> SE3:
    return SE3(SO3.from_matrix(P.rotation().matrix()), np.asarray(P.translation()))


def to_gtsam_navstate(s: InertialState) -> gtsam.NavState:
    import gtsam

    return gtsam.NavState(to_gtsam_pose(s.T_world_body), np.asarray(s.v_world_m_s))


@dataclass(frozen=True, slots=True)
class Coverage:
    """Whether the buffer covers ``[t0, t1]``: ``ok``, and the longest stretch without a sample
    that the interpolation would have to bridge (``gap_s``, inf when there is no sample at all)."""

    ok: bool
    gap_s: float


class ImuBuffer:
    """Every IMU sample received once, in time order (see the module docstring).

    ``add`` keeps the samples newer than the newest one held (an overlapping window adds nothing
    twice); ``forget_before`` drops what no later integration needs.
    """

    def __init__(self, max_gap_s: float = 0.05) -> None:
        if not (np.isfinite(max_gap_s) and max_gap_s > 0):
            raise ShapeError(f"max_gap_s must be > 0, got {max_gap_s}")
        self.max_gap_ns = int(round(max_gap_s * 1e9))
        self._t: I64 = np.zeros(0, dtype=np.int64)
        self._w: F64 = np.zeros((0, 3))
        self._a: F64 = np.zeros((0, 3))
        self.ignored_old = 0  # samples older than the newest one held, with a new stamp

    def __len__(self) -> int:
        return int(self._t.shape[0])

    @property
    def last_ns(self) -> int | None:
        return int(self._t[-1]) if len(self) else None

    def add(self, imu: ImuData) -> int:
        """Append the samples of ``imu`` newer than the newest held; returns how many."""
        t = np.asarray(imu.stamps_ns)
        last = self.last_ns
        new = np.ones(t.shape[0], dtype=bool) if last is None else t > last
        if last is not None:
            self.ignored_old += int(np.count_nonzero(~new & ~np.isin(t, self._t)))
        if not new.any():
            return 0
        self._t = np.concatenate([self._t, t[new]])
        self._w = np.concatenate([self._w, np.asarray(imu.gyro_rad_s)[new]])
        self._a = np.concatenate([self._a, np.asarray(imu.accel_m_s2)[new]])
        return int(np.count_nonzero(new))

    def forget_before(self, t_ns: int) -> None:
        """Drop samples that no integration from ``t_ns`` on needs (keeps the last one at or
        before ``t_ns``: it brackets the start)."""
        i = max(int(np.searchsorted(self._t, t_ns, side="right")) - 1, 0)
        self._t, self._w, self._a = self._t[i:], self._w[i:], self._a[i:]

    def coverage(self, t0_ns: int, t1_ns: int) -> Coverage:
        """Is ``[t0, t1]`` covered by samples no further apart than ``max_gap_s``?

        The support is the last sample at or before t0, the samples inside, and the first sample
        at or after t1; an end with no sample beyond it counts its distance to the nearest one.
        """
        if len(self) == 0:
            return Coverage(False, float("inf"))
        t = self._t
        lo = int(np.searchsorted(t, t0_ns, side="right")) - 1
        hi = int(np.searchsorted(t, t1_ns, side="left"))
        lo_c, hi_c = max(lo, 0), min(hi, len(t) - 1)
        support = t[lo_c : hi_c + 1]
        gaps = [float(np.diff(support).max()) if support.shape[0] > 1 else 0.0]
        gaps.append(float(abs(int(t[lo_c]) - t0_ns)) if lo < 0 else 0.0)
        gaps.append(float(abs(t1_ns - int(t[hi_c]))) if hi >= len(t) else 0.0)
        gap = max(gaps)
        return Coverage(gap <= self.max_gap_ns, gap * 1e-9)

    def pieces(self, t0_ns: int, t1_ns: int) -> tuple[F64, F64, F64]:
        """Midpoint readings over ``[t0, t1]``: (dt_s (M,), gyro (M, 3), accel (M, 3)).

        Readings are interpolated linearly between samples and held constant beyond the ends.
        """
        if t1_ns < t0_ns:
            raise ShapeError(f"integration interval runs backwards: {t0_ns} -> {t1_ns}")
        if len(self) == 0 or t1_ns == t0_ns:
            return np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3))
        t = self._t
        inside = t[(t > t0_ns) & (t < t1_ns)]
        br = np.concatenate([[t0_ns], inside, [t1_ns]]).astype(np.int64)
        dt = np.diff(br).astype(np.float64) * 1e-9
        # relative times keep ns-precision stamps exact in float64
        ts = (t - t0_ns).astype(np.float64)
        mid = (br[:-1] - t0_ns).astype(np.float64) + 0.5 * np.diff(br).astype(np.float64)
        w = np.stack([np.interp(mid, ts, self._w[:, k]) for k in range(3)], axis=1)
        a = np.stack([np.interp(mid, ts, self._a[:, k]) for k in range(3)], axis=1)
        return dt, w, a


class Preintegrator:
    """The preintegrated IMU since a start instant (a keyframe), advanced piece by piece.

    ``reset(t, bias)`` starts over at ``t`` with the bias to linearise about; ``advance(t)``
    integrates the buffer's samples up to ``t``. ``pim`` is the GTSAM object a
    ``CombinedImuFactor`` takes; ``predict`` propagates a state with it.
    """

    def __init__(self, params: gtsam.PreintegrationCombinedParams, buffer: ImuBuffer) -> None:
        import gtsam

        self.buffer = buffer
        self.pim = gtsam.PreintegratedCombinedMeasurements(params, gtsam.imuBias.ConstantBias())
        self.start_ns = 0
        self.end_ns = 0

    def reset(self, t_ns: int, bias: ImuBias) -> None:
        self.pim.resetIntegrationAndSetBias(to_gtsam_bias(bias))
        self.start_ns = self.end_ns = int(t_ns)

    def advance(self, t_ns: int) -> Coverage:
        """Integrate from the current end to ``t_ns``; nothing is integrated when the buffer does
        not cover the interval (the coverage says so)."""
        t_ns = int(t_ns)
        if t_ns < self.end_ns:
            raise ShapeError(f"IMU propagation cannot go back in time: {t_ns} < {self.end_ns} ns")
        cov = self.buffer.coverage(self.end_ns, t_ns)
        if not cov.ok:
            return cov
        dt, w, a = self.buffer.pieces(self.end_ns, t_ns)
        bg = np.asarray(self.pim.biasHat().gyroscope())
        ba = np.asarray(self.pim.biasHat().accelerometer())
        # GTSAM rotates a piece's specific force by the attitude at the start of the piece; turning
        # it by half the piece's rotation first applies the midpoint attitude instead (the bias is
        # put back, GTSAM subtracts it again).
        half = so3_exp(0.5 * (w - bg) * dt[:, None])
        a_mid = np.einsum("nij,nj->ni", half, a - ba) + ba
        integrate = self.pim.integrateMeasurement
        for k in range(dt.shape[0]):
            if dt[k] > 0:
                integrate(a_mid[k], w[k], float(dt[k]))
        self.end_ns = t_ns
        return cov

    @property
    def duration_s(self) -> float:
        return (self.end_ns - self.start_ns) * 1e-9

    def predict(self, state: InertialState, state_cov: F64 | None = None) -> tuple[InertialState, F64]:
        """The state at ``end_ns`` from ``state`` (at ``start_ns``), biases held, and its 15x15
        covariance in GTSAM's order [rotation (body), position (body), velocity (body), accel
        bias, gyro bias].

        ``state_cov``: the same 15x15 covariance of ``state`` (None: exactly known). The
        propagated one adds the preintegration noise to ``H state_cov H^T`` (Forster et al. 2017,
        eq. 63, with the biases' Jacobians from ``predict``).
        """
        H1 = np.zeros((9, 9), order="F")
        H2 = np.zeros((9, 6), order="F")
        nav = self.pim.predict(to_gtsam_navstate(state), to_gtsam_bias(state.bias), H1, H2)
        Q = np.asarray(self.pim.preintMeasCov())
        J = np.zeros((15, 15))
        J[:9, :9] = H1
        J[:9, 9:] = H2
        J[9:, 9:] = np.eye(6)
        P = Q.copy() if state_cov is None else J @ state_cov @ J.T + Q
        out = InertialState(self.end_ns, from_gtsam_pose(nav.pose()), np.asarray(nav.velocity()), state.bias)
        return out, 0.5 * (P + P.T)


def world_position_velocity_sigma(state: InertialState, cov15: F64) -> tuple[F64, F64]:
    """Per-axis standard deviations (world frame) of position and velocity from a 15x15
    covariance in GTSAM's body-frame order (see :meth:`Preintegrator.predict`)."""
    R = state.T_world_body.R
    Pp = R @ cov15[3:6, 3:6] @ R.T
    Pv = R @ cov15[6:9, 6:9] @ R.T
    return np.sqrt(np.maximum(np.diag(Pp), 0.0)), np.sqrt(np.maximum(np.diag(Pv), 0.0))


__all__ = ["Coverage", "ImuBias", "ImuBuffer", "InertialState", "Preintegrator", "from_gtsam_bias",
           "from_gtsam_pose", "preintegration_params", "to_gtsam_bias", "to_gtsam_navstate",
           "to_gtsam_pose", "world_position_velocity_sigma"]
