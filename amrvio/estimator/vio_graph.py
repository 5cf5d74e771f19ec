"""GTSAM pieces of the VIO back-end: keys, the camera and its robust noise, prior factors, the
smoother, the frames of the window, and the marginal covariance of a frame's state.

Variables of frame i: ``x i`` (Pose3, T_world_body), ``v i`` (world velocity), ``b i``
(imuBias.ConstantBias); landmark j: ``l j`` (Point3, world). The smoother's clock is the
keyframe ordinal (see :class:`WindowFrame`), so the window is a number of keyframes whatever
their spacing in time.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, SupportsFloat, SupportsIndex, SupportsInt

import numpy as np
from numpy.typing import ArrayLike, NDArray

from amrvio.errors import ShapeError
from amrvio.estimator.vio_types import PriorSigmas, VisualConfig
from amrvio.imu.propagation import InertialState, to_gtsam_bias, to_gtsam_pose
from amrvio.types.lie import SE3

if TYPE_CHECKING:
    import gtsam

F64 = NDArray[np.float64]

#: smoother time given to a frame that must be marginalised in the coming update
EXPIRED = -1e9

#: iSAM2's relinearisation threshold (rad, m, m/s and bias units alike: each tangent component)
RELINEARIZE_THRESHOLD = 0.01


def sym(c: str, i: int) -> int:
    import gtsam

    return int(gtsam.symbol(c, i))


def state_keys(i: int) -> tuple[int, int, int]:
    """(x i, v i, b i)."""
    return sym("x", i), sym("v", i), sym("b", i)


@dataclass(frozen=True, slots=True, eq=False)
class Camera:
    """K (3, 3) and its inverse, the extrinsics ``T_body_cam``, and their GTSAM forms with the
    Huber-robust pixel noise."""

    K: F64
    K_inv: F64
    T_body_cam: SE3
    cal: gtsam.Cal3_S2
    body_P_cam: gtsam.Pose3
    noise: gtsam.noiseModel.Base

    def factor(self, uv: F64, frame: int, landmark: int,
               noise: gtsam.noiseModel.Base | None = None) -> gtsam.GenericProjectionFactorCal3_S2:
        """Projection factor of landmark ``landmark`` seen at ``uv`` from frame ``frame`` (with
        ``noise``, else the camera's own)."""
        import gtsam

        return gtsam.GenericProjectionFactorCal3_S2(np.asarray(uv), self.noise if noise is None else noise,
                                                    sym("x", frame), sym("l", landmark), self.cal, False, False,
                                                    self.body_P_cam)


def pixel_noise(cfg: VisualConfig, sigma_px: float) -> gtsam.noiseModel.Base:
    """Isotropic pixel noise of ``sigma_px`` with the Huber loss of ``cfg`` (its corner at
    ``huber_px / pixel_sigma_px`` standard deviations)."""
    import gtsam

    return gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Huber.Create(cfg.huber_px / cfg.pixel_sigma_px),
                                          gtsam.noiseModel.Isotropic.Sigma(2, float(sigma_px)))


@functools.lru_cache(maxsize=512)
def age_noise(cfg: VisualConfig, age: int) -> gtsam.noiseModel.Base | None:
    """The pixel noise of an observation of a landmark first seen ``age`` frames ago (None: the
    camera's own; see ``VisualConfig.track_age_sigma_frames``)."""
    if cfg.track_age_sigma_frames <= 0 or age <= 0:
        return None
    return pixel_noise(cfg, cfg.pixel_sigma_px * float(np.sqrt(1.0 + age / cfg.track_age_sigma_frames)))


def make_camera(K: ArrayLike, T_body_cam: SE3, cfg: VisualConfig) -> Camera:
    import gtsam

    Km = np.asarray(K, dtype=np.float64)
    if Km.shape != (3, 3) or not np.all(np.isfinite(Km)) or Km[0, 0] <= 0 or Km[1, 1] <= 0:
        raise ShapeError(f"K must be a finite (3, 3) camera matrix with positive focal lengths, got {Km.tolist()}")
    cal = gtsam.Cal3_S2(Km[0, 0], Km[1, 1], Km[0, 1], Km[0, 2], Km[1, 2])
    noise = pixel_noise(cfg, cfg.pixel_sigma_px)
    K_inv = np.asarray(np.linalg.inv(Km), dtype=np.float64)
    return Camera(Km, K_inv, T_body_cam, cal, to_gtsam_pose(T_body_cam), noise)


def make_smoother(window_keyframes: int) -> gtsam.IncrementalFixedLagSmoother:
    """iSAM2 fixed-lag smoother keeping ``window_keyframes`` keyframe ordinals.

    iSAM2 puts new factors into the slots of removed ones (``findUnusedFactorSlots``). Without
    it, every factor ever added keeps a slot in iSAM2's factor lists: about 100 a frame (each
    frame's projection factors, removed at the next frame, and the marginalised ones), 49 783
    slots for 1 298 factors after 500 updates of ``bench_speed``'s 20 min drive, whose resident
    set grew by 1.2 MiB a minute (frames 2000-5750; 0.5 with reuse). A slot that is reused holds
    another factor, so a frame's own slots are removed only while they still hold its factors
    (:func:`live_slots`)."""
    import gtsam

    return gtsam.IncrementalFixedLagSmoother(float(window_keyframes - 1), smoother_params())


def smoother_params() -> gtsam.ISAM2Params:
    """iSAM2's parameters: relinearise a variable whose delta has a component beyond
    :data:`RELINEARIZE_THRESHOLD`, checked at every update; reuse the slots of removed factors."""
    import gtsam

    params = gtsam.ISAM2Params()
    params.setRelinearizeThreshold(RELINEARIZE_THRESHOLD)
    params.relinearizeSkip = 1
    params.findUnusedFactorSlots = True
    return params


def prior_sigmas_15(sig: PriorSigmas) -> F64:
    """Per-component sigmas in GTSAM NavState order + bias order (rot, pos, vel, accel, gyro)."""
    return np.r_[np.full(3, sig.rotation_rad), np.full(3, sig.position_m), np.full(3, sig.velocity_m_s),
                 np.full(3, sig.accel_bias_m_s2), np.full(3, sig.gyro_bias_rad_s)]


def add_priors(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, i: int, s: InertialState,
               sig: PriorSigmas) -> None:
    """Priors on the state of frame ``i`` (the initial state), and its initial values."""
    import gtsam

    sig15 = prior_sigmas_15(sig)
    X, V, B = state_keys(i)
    pose, bias = to_gtsam_pose(s.T_world_body), to_gtsam_bias(s.bias)
    graph.add(gtsam.PriorFactorPose3(X, pose, gtsam.noiseModel.Diagonal.Sigmas(sig15[:6])))
    graph.add(gtsam.PriorFactorVector(V, np.asarray(s.v_world_m_s), gtsam.noiseModel.Diagonal.Sigmas(sig15[6:9])))
    graph.add(gtsam.PriorFactorConstantBias(B, bias, gtsam.noiseModel.Diagonal.Sigmas(sig15[9:])))
    values.insert(X, pose)
    values.insert(V, np.asarray(s.v_world_m_s))
    values.insert(B, bias)


def marginal_covariance(smoother: gtsam.IncrementalFixedLagSmoother, values: gtsam.Values, i: int) -> F64:
    """15x15 joint covariance of frame ``i``'s state in GTSAM NavState order (rotation,
    position, velocity, all body frame; then accel bias, gyro bias); 1-3 ms for the newest frame
    after :func:`smoother_update`. (Two alternatives measured and dropped: marginalising in a
    separate update made it 33-44 ms; marginalising on iSAM2 directly, with the newest keys
    ordered last, lost the first keyframe's priors in ``marginalizeLeaves``.)"""
    X, V, B = state_keys(i)
    P = np.asarray(smoother.getISAM2().jointMarginalCovariance([X, V, B]).fullMatrix())
    T = np.eye(15)
    T[6:9, 6:9] = np.asarray(values.atPose3(X).rotation().matrix()).T  # velocity: world -> body
    cov = T @ P @ T.T
    return 0.5 * (cov + cov.T)


def smoother_update(smoother: gtsam.IncrementalFixedLagSmoother, graph: gtsam.NonlinearFactorGraph,
                    values: gtsam.Values, stamps: dict[int, float], remove: list[int], tick: int) -> list[int]:
    """One smoother update; returns the iSAM2 slots of the factors of ``graph``, in order.

    Every update also adds a throwaway variable ``z tick`` (with a prior) that it marginalises at
    once. The fixed-lag smoother gives iSAM2 its ordering constraints only in updates that
    marginalise something; without them iSAM2 orders the variables of all new factors last, and
    the newest frame's covariance (:func:`marginal_covariance`) then cost 20-60 ms instead of 1-3
    (measured on the handheld and forward-stop-turn simulations: per-frame CPU p90 37 -> 25 ms and
    46 -> 17 ms, largest 98 -> 32 ms and 78 -> 31 ms, the same estimates)."""
    import gtsam

    Z = sym("z", tick)
    graph.add(gtsam.PriorFactorPoint3(Z, np.zeros(3), gtsam.noiseModel.Isotropic.Sigma(3, 1.0)))
    values.insert(Z, np.zeros(3))
    ts: dict[SupportsInt | SupportsIndex, SupportsFloat | SupportsIndex] = {k: v for k, v in stamps.items()}
    ts[Z] = EXPIRED
    smoother.update(graph, values, ts, remove)
    return [int(i) for i in smoother.getISAM2Result().getNewFactorsIndices()]


def live_slots(smoother: gtsam.IncrementalFixedLagSmoother, slots: Sequence[int],
               factors: Sequence[object]) -> list[int]:
    """Those of ``slots`` that still hold the factor put there (``factors``, the same order): a
    slot whose factor the smoother marginalised is empty, or holds a newer factor once reused."""
    graph = smoother.getFactors()
    return [s for s, f in zip(slots, factors, strict=True) if graph.exists(s) and graph.at(s) is f]


@dataclass(slots=True)
class WindowFrame:
    """A frame in the smoother. ``index``: its variables' index; ``ordinal``: its smoother time,
    the keyframe count (a frame that is not a keyframe takes the ordinal the next keyframe will
    have, and is dropped when the next frame arrives); ``slots``: iSAM2 slots of its projection
    factors, removed when it is dropped (so that marginalising it links no landmarks), and
    ``factors`` those factors, to tell whether a slot still holds them (:func:`live_slots`)."""

    index: int
    t_ns: int
    ordinal: int
    keyframe: bool
    slots: list[int] = field(default_factory=list)
    factors: Sequence[object] = ()


__all__ = ["EXPIRED", "RELINEARIZE_THRESHOLD", "Camera", "WindowFrame", "add_priors", "age_noise", "live_slots",
           "make_camera", "make_smoother", "marginal_covariance", "prior_sigmas_15", "smoother_params",
           "smoother_update", "state_keys", "sym"]
