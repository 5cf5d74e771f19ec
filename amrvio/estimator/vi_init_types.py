"""Values of the visual-inertial initialiser (amrvio.estimator.vi_init): configuration, status and
the frozen report it returns. Frames: ``vo`` is the frame of the up-to-scale VO poses, ``cam`` the
camera (x right, y down, z forward), ``body`` the IMU; metric = ``scale`` x VO units.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


class ViInitStatus(enum.Enum):
    """The outcome; every value but OK names the first check that failed (module vi_init, in order)."""

    OK = "ok"
    TOO_FEW_KEYFRAMES = "too_few_keyframes"  # fewer than min_keyframes, or shorter than min_duration_s
    IMU_MISSING = "imu_missing"  # the IMU does not cover the keyframes
    ROTATION_MISMATCH = "rotation_mismatch"  # VO and gyro rotations disagree (extrinsic, time offset)
    INSUFFICIENT_EXCITATION = "insufficient_excitation"  # too little acceleration: scale unobservable
    ILL_CONDITIONED = "ill_conditioned"  # the linear system for scale, gravity, velocities
    NEGATIVE_SCALE = "negative_scale"  # VO translation against the IMU's
    BAD_GRAVITY_NORM = "bad_gravity_norm"  # the free gravity vector is far from gravity_m_s2
    IMPLAUSIBLE_BIAS = "implausible_bias"  # a bias beyond max_gyro_bias / max_accel_bias
    SCALE_UNCERTAIN = "scale_uncertain"  # the scale's standard deviation is above max_scale_rel_std
    GRAVITY_UNCERTAIN = "gravity_uncertain"  # the gravity direction's std is above max_gravity_std_deg
    SCALE_DRIFT = "scale_drift"  # the VO's scale changes across the window by more than max_scale_drift


@dataclass(frozen=True, slots=True)
class ViInitGates:
    """Thresholds of the checks. ``min_accel_std_m_s2``: the excitation gate, checked before solving
    (RMS acceleration change over the window, gravity-free); ``min_rotation_deg``: below it the
    advice asks for a turn (it separates the accelerometer bias from gravity; not a gate);
    ``max_condition_number`` of the column-equilibrated, whitened linear system;
    ``max_gravity_norm_error``: relative error of the free gravity vector's norm;
    ``max_rotation_rms_deg``: VO against gyro rotation per keyframe interval, after the bias;
    ``min_translation_snr``: the VO camera must travel this many times its jitter (checked before
    solving, with the acceleration: an IMU on a vibrating platform at rest shows acceleration
    spread without motion); ``max_scale_rel_std``: scale standard deviation / scale (0.8 %: a 2 % error is 2.5 standard
    deviations); ``max_gravity_std_deg``: standard deviation of the gravity direction (1 deg is 3);
    ``max_scale_drift``: how much the VO's scale may change from the window's first keyframe to its
    last (0.1: one scale is then within 5 % of either end's)."""

    min_accel_std_m_s2: float = 0.25
    min_translation_snr: float = 10.0
    min_rotation_deg: float = 20.0
    max_condition_number: float = 1e4
    max_gravity_norm_error: float = 0.1
    max_rotation_rms_deg: float = 1.0
    max_gyro_bias_rad_s: float = 0.2
    max_accel_bias_m_s2: float = 0.6
    max_scale_rel_std: float = 0.008
    max_gravity_std_deg: float = 0.33
    max_scale_drift: float = 0.1


@dataclass(frozen=True, slots=True)
class ViInitConfig:
    """``gravity_m_s2``: local gravity; ``min_keyframes`` / ``min_duration_s``: the smallest window;
    ``gyro_bias_sigma_rad_s`` / ``accel_bias_sigma_m_s2``: zero-mean bias priors of the MAP step
    (used when no :class:`ViBiasPrior` is given); ``lowpass_s``: the acceleration is averaged over
    bins of this length for the excitation figures (vibration is not excitation);
    ``solve_degenerate``: also solve a window that fails a gate (for benchmarks; the status still
    names the failed gate)."""

    gates: ViInitGates = field(default_factory=ViInitGates)
    gravity_m_s2: float = 9.81
    min_keyframes: int = 5
    min_duration_s: float = 1.0
    gyro_bias_sigma_rad_s: float = 0.05
    accel_bias_sigma_m_s2: float = 0.1
    lowpass_s: float = 0.1
    solve_degenerate: bool = False


@dataclass(frozen=True, slots=True, eq=False)
class ViBiasPrior:
    """A prior on the biases (for example from amrvio.imu.static_init): means and per-axis std (3,)."""

    gyro_bias_rad_s: F64
    gyro_bias_std_rad_s: F64
    accel_bias_m_s2: F64
    accel_bias_std_m_s2: F64


@dataclass(frozen=True, slots=True, eq=False)
class ViExcitation:
    """Motion in the window, measured before solving (gravity-free: the VO rotations carry the
    specific force into one frame, where gravity is a constant that a spread ignores).

    accel_std_cam_m_s2 (3,): RMS of the acceleration change along the camera's x (right), y (down)
    and z (forward) axes; rotation_range_deg: largest angle between two keyframe orientations;
    rotation_range_cam_deg (3,): range of the rotation about the first camera's x, y, z axes;
    translation_snr: how far the VO camera travels (largest distance from its mean position) over
    its keyframe-to-keyframe jitter (the smallest RMS difference of orders 2-4 over its white-noise
    gain: :func:`amrvio.estimator.vi_init_advice.translation_snr`): under 5 for a camera at rest
    or only rotating, tens to hundreds for a camera that moves; scale needs the camera to translate.
    """

    duration_s: float
    n_keyframes: int
    accel_std_cam_m_s2: F64
    rotation_range_deg: float
    rotation_range_cam_deg: F64
    translation_snr: float

    @property
    def accel_std_m_s2(self) -> float:
        return float(np.sqrt(np.sum(np.square(self.accel_std_cam_m_s2))))


@dataclass(frozen=True, slots=True, eq=False)
class ViInitFigures:
    """How the solve went. rotation_rms_deg: VO against gyro rotation per interval after the gyro
    bias; condition_number: of the linear system; gravity_norm_residual_m_s2: |g| of the linear
    solution minus gravity_m_s2; linear_scale: its scale; vo_position_sigma_m and
    vo_rotation_sigma_deg: the keyframe-interval noise the MAP step estimated from its residuals;
    chi2_per_dof: of the MAP step (noise model included); iterations: Gauss-Newton iterations."""

    rotation_rms_deg: float
    condition_number: float = float("nan")
    gravity_norm_residual_m_s2: float = float("nan")
    linear_scale: float = float("nan")
    vo_position_sigma_m: float = float("nan")
    vo_rotation_sigma_deg: float = float("nan")
    accel_noise_factor: float = float("nan")
    chi2_per_dof: float = float("nan")
    iterations: int = 0
    scale_drift: float = float("nan")
    scale_drift_std: float = float("nan")


@dataclass(frozen=True, slots=True, eq=False)
class ViInitState:
    """The estimated state. scale: metric = scale x VO units, with scale_std from the marginal
    covariance of the MAP step; gravity_vo (3,) m/s^2 in the VO frame and gravity_std_deg;
    gyro and accelerometer biases (3,) with std (3,), the accelerometer's at the last keyframe
    (it is a random walk over the window); velocities_vo (K, 3) m/s of the body at the keyframes;
    R_world_vo (3, 3): a gravity-aligned world (z up, yaw free, set to 0) from the VO frame;
    stamps_ns (K,)."""

    scale: float
    scale_std: float
    gravity_vo: F64
    gravity_std_deg: float
    gyro_bias_rad_s: F64
    gyro_bias_std_rad_s: F64
    accel_bias_m_s2: F64
    accel_bias_std_m_s2: F64
    velocities_vo: F64
    R_world_vo: F64
    stamps_ns: I64


@dataclass(frozen=True, slots=True, eq=False)
class ViInitResult:
    """What the initialiser returns: ``status``, plain ``advice`` (empty when OK), the
    ``excitation`` figures (None when the input stopped it earlier), the solve ``figures`` and the
    ``state``: None when the MAP step did not run; after it, present whatever the status (with
    SCALE_UNCERTAIN, GRAVITY_UNCERTAIN or an implausible accelerometer bias it is there to be read,
    not used; with ``solve_degenerate`` every gate's failure still solves)."""

    status: ViInitStatus
    advice: str
    excitation: ViExcitation | None = None
    figures: ViInitFigures | None = None
    state: ViInitState | None = None

    @property
    def ok(self) -> bool:
        return self.status is ViInitStatus.OK

    @property
    def scale(self) -> float:
        return self.state.scale if self.state is not None else float("nan")

    @property
    def scale_std(self) -> float:
        return self.state.scale_std if self.state is not None else float("nan")

    def health_fields(self) -> dict[str, float | str]:
        """Flat fields for a health record (``vi_init_*``; NaN where not computed)."""
        nan = float("nan")
        ex, fig, st = self.excitation, self.figures, self.state
        acc = ex.accel_std_cam_m_s2 if ex is not None else np.full(3, nan)
        return {
            "vi_init_status": self.status.value,
            "vi_init_scale": self.scale,
            "vi_init_scale_std": self.scale_std,
            "vi_init_gravity_std_deg": st.gravity_std_deg if st is not None else nan,
            "vi_init_accel_std_x_m_s2": float(acc[0]),
            "vi_init_accel_std_y_m_s2": float(acc[1]),
            "vi_init_accel_std_z_m_s2": float(acc[2]),
            "vi_init_rotation_range_deg": ex.rotation_range_deg if ex is not None else nan,
            "vi_init_translation_snr": ex.translation_snr if ex is not None else nan,
            "vi_init_condition_number": fig.condition_number if fig is not None else nan,
            "vi_init_gravity_norm_residual_m_s2": fig.gravity_norm_residual_m_s2 if fig is not None else nan,
            "vi_init_advice": self.advice,
        }


def fmt_num(x: float, digits: int = 2) -> str:
    """A number for advice text ('n/a' when not finite)."""
    return f"{x:.{digits}f}" if math.isfinite(x) else "n/a"
