"""Values of the sliding-window VIO back-end: its configuration, its inputs and its results.

The back-end itself is :class:`amrvio.estimator.vio_backend.VioBackend`; the consistency checks
whose report each keyframe result carries are in :mod:`amrvio.estimator.vio_checks`.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ConfigError, ShapeError
from amrvio.estimator.vio_checks import CheckConfig, ConsistencyReport
from amrvio.imu.propagation import InertialState
from amrvio.types.sensors import ImuNoise

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


def _positive(prefix: str, obj: object, names: tuple[str, ...]) -> None:
    for name in names:
        v = float(getattr(obj, name))
        if not (np.isfinite(v) and v > 0):
            raise ConfigError(f"{prefix}.{name} must be a positive number, got {v}")


@dataclass(frozen=True, slots=True)
class VisualConfig:
    """The visual factors and landmarks.

    pixel_sigma_px: standard deviation of an observation; huber_px: residual where the Huber
    loss turns linear; gate_px: an observation further than this from its prediction (IMU-
    predicted pose, current landmark) is not used, and a new landmark must reproject within it
    in every view. min_parallax_deg: angle the rays of a track must span before it becomes a
    landmark. 2 deg, not 1: the noise of a low-parallax landmark's depth biases the scale it
    gives the smoother. On the simulator's forward-stop-turn (376x240), the speed ran 3-7 % low
    through the drive with 1 deg; replacing the tracks by their true projections plus white noise
    took 2.3 s to reach 2 % scale with 0.3 px of noise and 0.8 s with 0.1 px, and removing the
    tracks more than 0.5 px off did not help (the noise, not outliers). With 2 deg the median
    time to 2 % over 4 seeds went from 3.1 s to 1.2 s and the replay's median scale error from
    2.3 % to 1.4 % (bench_vio_pipeline). min_depth_m / max_depth_m: accepted landmark depths.
    keyframe_parallax_deg: a frame becomes a keyframe when the landmarks it sees moved this much
    (median angle at the landmark between its camera centre and the last keyframe's), or when
    it sees fewer than min_tracked_landmarks landmarks and its camera moved the baseline that
    makes this angle at the typical depth of the landmarks seen lately
    (:func:`amrvio.estimator.vio_triangulate.keyframe_due`); other frames stay in the window
    only until the next one.
    landmark_prior_range: a triangulated landmark gets an isotropic prior at its triangulated
    position with a standard deviation of this many times its range from its first camera (0:
    none). It keeps the linear system determined when the rays of a landmark become nearly
    parallel or its observations are down-weighted, which made iSAM2 raise "indeterminate linear
    system" (a solver failure, then a re-initialisation); at 3 ranges it holds 0.35 % of the
    depth information that two views at ``min_parallax_deg`` = 2 deg give at f = 229 px, 0.09 %
    at 458 px (see
    :func:`amrvio.estimator.vio_triangulate.landmark_prior_share`). track_age_sigma_frames: a
    frame's observation of a landmark whose first keyframe is ``a`` frames older (frames given
    to the back-end) has a standard
    deviation of pixel_sigma_px * sqrt(1 + a / track_age_sigma_frames) (0: pixel_sigma_px for
    every observation): a KLT track drifts as it ages (against the simulator's truth on a
    forward-stop-turn drive: median 0.1 px after 1 frame, 0.4 px after 4-8, 0.56 px after
    16-32, and 20-32 % of the observations of tracks older than 3 frames more than 1 px off),
    and independent 1 px noise on every observation over-weights old tracks.
    max_log_scale: when a landmark's distance from the camera differs from its distance from
    its first keyframe by more than this (natural log of the ratio; 0.2 = 22 %), the observation
    is not used and the landmark ends: its track goes on as a new pending track, triangulated
    again from the views that follow (0: no limit). The KLT follows a patch with a
    translation-only model, so a track slides over the surface as its patch grows or shrinks:
    against the simulator's truth on forward-stop-turn its median error was 0.09 px below 2 %
    of scale change, 0.34 px at 5-10 %, 0.89 px at 10-20 % and 1.95 px at 20-50 %, and those
    tracks held the smoother's speed 7 % low through the braking (true projections with 0.3 px
    of white noise: within 2 %). ORB-SLAM's map points have a distance range for the same reason.
    """

    pixel_sigma_px: float = 1.0
    huber_px: float = 2.0
    gate_px: float = 10.0
    min_parallax_deg: float = 2.0
    min_depth_m: float = 0.1
    max_depth_m: float = 200.0
    keyframe_parallax_deg: float = 1.0
    min_tracked_landmarks: int = 30
    landmark_prior_range: float = 3.0
    track_age_sigma_frames: float = 10.0
    max_log_scale: float = 0.2

    def __post_init__(self) -> None:
        _positive("vio.visual", self, ("pixel_sigma_px", "huber_px", "gate_px", "min_depth_m", "max_depth_m"))
        for name in ("min_parallax_deg", "keyframe_parallax_deg"):
            v = float(getattr(self, name))
            if not 0 <= v < 90:
                raise ConfigError(f"vio.visual.{name} must be in [0, 90) degrees, got {v}")
        if self.max_depth_m <= self.min_depth_m:
            raise ConfigError("vio.visual.max_depth_m must be larger than vio.visual.min_depth_m")
        if not (np.isfinite(self.landmark_prior_range) and self.landmark_prior_range >= 0):
            raise ConfigError(f"vio.visual.landmark_prior_range must be a number >= 0, got {self.landmark_prior_range}")
        if not (np.isfinite(self.max_log_scale) and self.max_log_scale >= 0):
            raise ConfigError(f"vio.visual.max_log_scale must be a number >= 0, got {self.max_log_scale}")
        if not (np.isfinite(self.track_age_sigma_frames) and self.track_age_sigma_frames >= 0):
            raise ConfigError(f"vio.visual.track_age_sigma_frames must be a number >= 0, got "
                              f"{self.track_age_sigma_frames}")
        if not 0 <= self.min_tracked_landmarks <= 100000:
            raise ConfigError(f"vio.visual.min_tracked_landmarks must be in [0, 100000], got "
                              f"{self.min_tracked_landmarks}")


@dataclass(frozen=True, slots=True)
class VioConfig:
    """The sliding-window smoother.

    imu: noise densities and bias random walks of the IMU (Kalibr convention; default: the
    ADIS16448 of EuRoC). imu_noise_scale: factor on all four (a calibration on the bench does not
    see the vibration of a flying or driving platform: on the EuRoC V1_01 flight, 0.5 s IMU-only
    predictions from the ground truth miss it by 8.5 to 9.5 times the sigmas of its sensor.yaml's
    values (RMS), and by 0.9 with a factor of 10; 1 here, the noise as given). The pipeline's
    ``vio.imu_noise_scale`` is 3: on the replay of that flight with its recorded IMU (4 render seeds)
    the median scale error was 1.10 % at 752x480 with 1 (3 seeds over 1 %), 0.76 % with 3, and the
    SE3 ATE at 376x240 0.023 m with 1, 0.014 m with 3 (scale error 0.15 and 0.17 %); 10 took
    376x240's scale error to 0.35-0.66 %. The simulator's and MH_01's IMUs are synthesised with the
    datasheet noise, which 3 overstates: MH_01's median scale error 0.31 -> 0.79 % (README).
    gravity_m_s2: local gravity. window_keyframes:
    frames in the fixed-lag smoother (the keyframes and the newest frame); older keyframes, and
    the landmarks first seen by them, are marginalised. max_imu_gap_s: longest stretch without an IMU sample that
    integration may bridge. iterations: smoother updates per frame. visual: the visual factors.
    checks: thresholds of the consistency checks.
    """

    imu: ImuNoise = field(default_factory=ImuNoise.euroc_adis16448)
    imu_noise_scale: float = 1.0
    gravity_m_s2: float = 9.81
    window_keyframes: int = 15
    max_imu_gap_s: float = 0.05
    iterations: int = 1
    visual: VisualConfig = field(default_factory=VisualConfig)
    checks: CheckConfig = field(default_factory=CheckConfig)

    def __post_init__(self) -> None:
        _positive("vio", self, ("imu_noise_scale", "gravity_m_s2", "max_imu_gap_s"))
        if not 2 <= self.window_keyframes <= 1000:
            raise ConfigError(f"vio.window_keyframes must be in [2, 1000], got {self.window_keyframes}")
        if not 1 <= self.iterations <= 50:
            raise ConfigError(f"vio.iterations must be in [1, 50], got {self.iterations}")

    def imu_model(self) -> ImuNoise:
        """``imu`` with every density and random walk multiplied by ``imu_noise_scale``."""
        f, n = self.imu_noise_scale, self.imu
        return ImuNoise(n.gyro_noise_density * f, n.gyro_random_walk * f, n.accel_noise_density * f,
                        n.accel_random_walk * f, n.rate_hz)


@dataclass(frozen=True, slots=True, eq=False)
class VisualObservations:
    """Landmarks seen in one frame: ``ids`` (N,) int64, distinct; ``uv_px`` (N, 2) undistorted
    pinhole pixels (the camera matrix K given to the back-end)."""

    ids: I64
    uv_px: F64

    def __post_init__(self) -> None:
        ids = np.array(self.ids, dtype=np.int64).reshape(-1)
        uv = np.array(self.uv_px, dtype=np.float64)
        if uv.shape != (ids.shape[0], 2):
            raise ShapeError(f"observations: ids (N,) and uv_px (N, 2) expected, got {ids.shape}, {uv.shape}")
        if not np.all(np.isfinite(uv)):
            raise ShapeError("observations: pixel coordinates must be finite")
        if np.unique(ids).shape[0] != ids.shape[0]:
            raise ShapeError("observations: a landmark id appears twice in one frame")
        ids.setflags(write=False)
        uv.setflags(write=False)
        object.__setattr__(self, "ids", ids)
        object.__setattr__(self, "uv_px", uv)

    def __len__(self) -> int:
        return int(self.ids.shape[0])

    @staticmethod
    def empty() -> VisualObservations:
        return VisualObservations(np.zeros(0, dtype=np.int64), np.zeros((0, 2)))


@dataclass(frozen=True, slots=True)
class PriorSigmas:
    """Standard deviations of the initial state (the initialiser's uncertainty). Rotation and
    position also fix the gauge (yaw and position are unobservable in VIO). ``landmark_m``: of
    each coordinate of the initialiser's landmarks."""

    rotation_rad: float = 0.01
    position_m: float = 0.01
    velocity_m_s: float = 0.1
    gyro_bias_rad_s: float = 5e-3
    accel_bias_m_s2: float = 0.1
    landmark_m: float = 0.05

    def __post_init__(self) -> None:
        for name in ("rotation_rad", "position_m", "velocity_m_s", "gyro_bias_rad_s", "accel_bias_m_s2",
                     "landmark_m"):
            v = float(getattr(self, name))
            if not (np.isfinite(v) and v > 0):
                raise ConfigError(f"prior sigma {name} must be a positive number, got {v}")


@dataclass(frozen=True, slots=True, eq=False)
class VioInitialState:
    """What the VI initialiser hands over: the state of the first keyframe in a gravity-aligned
    world (z up) with metric scale, its uncertainty, and optionally landmarks already located
    (``landmark_ids`` (L,), ``landmarks_world`` (L, 3)). Such a landmark enters the window at the
    first keyframe that sees it, with a prior of ``sigmas.landmark_m`` and no parallax needed (so
    a platform that starts at rest is held by them); other tracks are triangulated from the
    window's poses once their rays have parallax."""

    state: InertialState
    sigmas: PriorSigmas = field(default_factory=PriorSigmas)
    landmark_ids: I64 = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    landmarks_world: F64 = field(default_factory=lambda: np.zeros((0, 3)))

    def __post_init__(self) -> None:
        ids = np.array(self.landmark_ids, dtype=np.int64).reshape(-1)
        X = np.array(self.landmarks_world, dtype=np.float64)
        if X.shape != (ids.shape[0], 3) or not np.all(np.isfinite(X)):
            raise ShapeError(f"initial landmarks: ids (L,) and finite points (L, 3) expected, got "
                             f"{ids.shape}, {X.shape}")
        object.__setattr__(self, "landmark_ids", ids)
        object.__setattr__(self, "landmarks_world", X)


class EstimateKind(enum.Enum):
    """Where a pose comes from: the initial state, the smoother (a frame given to ``add_frame``),
    or IMU propagation from the newest frame of the window, for a tracked frame (PROPAGATED) or a
    dropped / lost one (BRIDGED)."""

    INITIAL = "initial"
    SMOOTHED = "smoothed"
    PROPAGATED = "propagated"
    BRIDGED = "bridged"


class VioStatus(enum.Enum):
    """OK; IMU_GAP: the IMU does not cover the interval (the back-end needs a new initialisation);
    SOLVER_FAILED: the smoother raised (likewise); NOT_INITIALISED: ``initialise`` was not called,
    or the last failure left the back-end without a state."""

    OK = "ok"
    IMU_GAP = "imu_gap"
    SOLVER_FAILED = "solver_failed"
    NOT_INITIALISED = "not_initialised"


@dataclass(frozen=True, slots=True, eq=False)
class VioEstimate:
    """The state at ``t_ns`` (None unless status is OK) and per-axis world-frame standard
    deviations of position and velocity (None when not computed); ``since_smoothed_s``: time
    from the newest smoothed frame (0 for a smoothed frame)."""

    t_ns: int
    kind: EstimateKind
    status: VioStatus
    state: InertialState | None = None
    position_sigma_m: F64 | None = None
    velocity_sigma_m_s: F64 | None = None
    since_smoothed_s: float = 0.0

    @property
    def ok(self) -> bool:
        return self.status is VioStatus.OK and self.state is not None


@dataclass(frozen=True, slots=True)
class VisualStats:
    """The frame's observations: received, used as factors, rejected by the gate, landmarks
    created; landmarks in the window; RMS reprojection error (px) of this frame's factors after
    the update (None without any)."""

    n_observations: int = 0
    n_used: int = 0
    n_gated: int = 0
    n_new_landmarks: int = 0
    n_window_landmarks: int = 0
    rms_px: float | None = None


@dataclass(frozen=True, slots=True, eq=False)
class FrameResult:
    """One ``add_frame``: the optimised estimate, whether the frame became a keyframe, the IMU
    prediction it started from (the checks compare the two), the visual statistics, the
    consistency report (None when the update failed) and the wall time of the call (s)."""

    estimate: VioEstimate
    keyframe: bool
    predicted: InertialState | None
    visual: VisualStats
    checks: ConsistencyReport | None
    solve_s: float


__all__ = ["EstimateKind", "FrameResult", "PriorSigmas", "VioConfig", "VioEstimate", "VioInitialState", "VioStatus",
           "VisualConfig", "VisualObservations", "VisualStats"]
