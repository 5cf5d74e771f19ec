"""Values of the visual-inertial stage (:class:`amrvio.pipeline.vio_stage.VioStage`): its configuration,
its per-frame input, and what it reports for one frame (:class:`VioReport`, its ``health.csv`` columns)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import Enum

import numpy as np
from numpy.typing import NDArray

from amrvio.diagnostics.health import FrameHealth
from amrvio.errors import ConfigError
from amrvio.estimator.vi_init import ViInitResult
from amrvio.estimator.vio_checks import ConsistencyReport
from amrvio.estimator.vio_types import VioEstimate
from amrvio.frontend.tracking_types import TrackOutcome
from amrvio.frontend.tracks import TrackSet
from amrvio.imu.propagation import InertialState
from amrvio.imu.static_init import StaticInitResult
from amrvio.pipeline.pose_book import PoseBook
from amrvio.pipeline.zero_velocity import ZeroVelocity, ZeroVelocityConfig
from amrvio.types.lie import SE3, se3_matrix_inverse, so3_exp, so3_log
from amrvio.types.sensors import ImuData, ImuNoise, WheelData

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


@dataclass(frozen=True, slots=True)
class DynamicInitConfig:
    """The VIO stage's dynamic initialisation: ``min_keyframes`` / ``max_window_s``: the VO
    keyframes it needs, and the longest span it uses; ``max_scale_rel_std`` /
    ``max_gravity_std_deg``: the scale std / scale and gravity-direction std it accepts (looser
    than the initialiser's own gates for a lone window: the smoother refines both afterwards);
    ``max_scale_drift``: the VO's scale change across the window it accepts (else: its newer half)."""

    min_keyframes: int = 8
    max_window_s: float = 10.0
    max_scale_rel_std: float = 0.015
    max_gravity_std_deg: float = 1.0
    max_scale_drift: float = 0.1

    def __post_init__(self) -> None:
        if not 3 <= self.min_keyframes <= 1000:
            raise ConfigError(f"vio.dynamic_init.min_keyframes must be in [3, 1000], got {self.min_keyframes}")
        if not (np.isfinite(self.max_window_s) and self.max_window_s >= 1.0):
            raise ConfigError(f"vio.dynamic_init.max_window_s must be >= 1 s, got {self.max_window_s}")
        for name, hi in (("max_scale_rel_std", 1.0), ("max_gravity_std_deg", 90.0), ("max_scale_drift", 10.0)):
            if not 0 < getattr(self, name) < hi:
                raise ConfigError(f"vio.dynamic_init.{name} must be in (0, {hi:g}), got {getattr(self, name)}")


@dataclass(frozen=True, slots=True)
class VioStageConfig:
    """``enabled``: run VIO when the recording has an IMU; ``imu_noise_scale``: factor on the
    IMU's noise densities and random walks, 3 (why: :class:`amrvio.estimator.vio_types.VioConfig`);
    ``window_keyframes``: keyframes in the fixed-lag smoother; ``static_init_s``: still this long
    from the start starts the smoother at rest (0: never); ``dynamic_init``: the dynamic
    initialisation's needs and gates (:class:`DynamicInitConfig`); ``min_tracks``: fewer tracks
    than this and a frame is bridged by the IMU; ``reinit_on_check_failure``: re-initialise when
    a consistency check fails; ``reinit_after_s``: a scale or bias-drift check (each judged over
    the last second) re-initialises only once it has failed on every keyframe for this long, the
    other checks at once (see :meth:`BodyTrack.restart_due`). 2 s, twice the checks' window: on
    the replay of V1_01 (4 render seeds, bench_vio_pipeline) these checks caught excursions of
    15-20 % over 0.2 m of slow flight that lasted 0.5-0.6 s and corrected themselves, and each
    restart lost the scale the smoother's prior held: the median scale error was 1.36 % with
    restarts at once, 1.16 % after 0.5 s, 0.51 % after 2 s (none lasted that long). On MH_01
    hand-held the restarts helped (0.25 % at once, 1.28 % after 2 s; its target is 2 %);
    ``wheel_sigma_m_s``: standard deviation of the wheel-odometry velocity (forward speed, and the zero sideways
    and vertical speed of a ground robot) when the recording has wheel odometry (0, the default: not used; a
    wheel file does not say the platform is a ground robot; ``amrvio run --wheels`` sets 0.05);
    ``max_smear_px``: a frame whose predicted smear (the gyro's rotation plus the translation,
    :mod:`amrvio.pipeline.smear_motion`) is larger is bridged by the IMU whatever the blur gate
    said, except one without an exposure time that PnP posed; ``track_smear_px``: see
    :mod:`amrvio.pipeline.vio_blur`; ``zero_velocity``: :mod:`amrvio.pipeline.zero_velocity`."""

    enabled: bool = True
    imu_noise_scale: float = 3.0
    window_keyframes: int = 10
    static_init_s: float = 0.4
    dynamic_init: DynamicInitConfig = field(default_factory=DynamicInitConfig)
    min_tracks: int = 10
    reinit_on_check_failure: bool = True
    reinit_after_s: float = 2.0
    wheel_sigma_m_s: float = 0.0
    max_smear_px: float = 8.0
    track_smear_px: float = 4.0
    zero_velocity: ZeroVelocityConfig = field(default_factory=ZeroVelocityConfig)

    def __post_init__(self) -> None:
        if not (np.isfinite(self.imu_noise_scale) and self.imu_noise_scale > 0):
            raise ConfigError(f"vio.imu_noise_scale must be > 0, got {self.imu_noise_scale}")
        if not 2 <= self.window_keyframes <= 200:
            raise ConfigError(f"vio.window_keyframes must be in [2, 200], got {self.window_keyframes}")
        if not (np.isfinite(self.static_init_s) and self.static_init_s >= 0):
            raise ConfigError(f"vio.static_init_s must be >= 0, got {self.static_init_s}")
        if not (np.isfinite(self.wheel_sigma_m_s) and self.wheel_sigma_m_s >= 0):
            raise ConfigError(f"vio.wheel_sigma_m_s must be >= 0, got {self.wheel_sigma_m_s}")
        if not (self.max_smear_px > 0 and 0 <= self.track_smear_px <= self.max_smear_px):
            raise ConfigError(f"vio.max_smear_px must be > 0 and vio.track_smear_px in [0, max_smear_px], got "
                              f"{self.max_smear_px} and {self.track_smear_px}")
        if not (np.isfinite(self.reinit_after_s) and 0 <= self.reinit_after_s <= 60):
            raise ConfigError(f"vio.reinit_after_s must be in [0, 60] s, got {self.reinit_after_s}")
        if self.min_tracks < 0:
            raise ConfigError(f"vio.min_tracks must be >= 0, got {self.min_tracks}")


@dataclass(frozen=True, slots=True, eq=False)
class VioFrameInput:
    """One frame for the stage: ``t_ns``; ``imu``: samples since the previous frame (may overlap);
    ``usable``: the tracks were tracked into this image (not blurred, dropped or repeated);
    ``ids`` (N,) / ``uv`` (N, 2): the tracks, undistorted pinhole pixels; ``vo_keyframe``:
    (segment, keyframe id) when the VO made this frame a keyframe; ``smear_px``: the motion smear
    predicted for the exposure (the diagnostics'; NaN when unknown); ``exposure_known``: the frame
    carries its exposure time (else the prediction assumed one); ``pnp_posed``: the tracker posed
    the frame by PnP on its map points (outcome TRACKED)."""

    t_ns: int
    imu: ImuData | None
    usable: bool
    ids: I64
    uv: F64
    vo_keyframe: tuple[int, int] | None = None
    smear_px: float = float("nan")
    exposure_known: bool = True
    pnp_posed: bool = False


#: tracker outcomes whose tracks the stage does not take: not moved into the frame's image, or
#: moved into a blurred one (BLURRED_REFERENCE; the stage bridges blurred frames with the IMU)
UNTRACKED = (TrackOutcome.SKIPPED_BLURRED, TrackOutcome.PREDICTED, TrackOutcome.TRACKED_BLURRED,
             TrackOutcome.BLURRED_REFERENCE, TrackOutcome.REPEATED)


def vio_input(t_ns: int, imu: ImuData | None, outcome: TrackOutcome, tracks: TrackSet,
              vo_keyframe: tuple[int, int] | None, health: FrameHealth | None = None) -> VioFrameInput:
    """The stage's input from the tracker's outcome, its live tracks and the frame's health."""
    smear = float("nan") if health is None or health.blur.smear_px_pred is None else health.blur.smear_px_pred
    return VioFrameInput(t_ns, imu, outcome not in UNTRACKED, tracks.ids.copy(), tracks.pts.copy(), vo_keyframe, smear,
                         health is None or health.exposure.exposure_s is not None, outcome is TrackOutcome.TRACKED)


@dataclass(frozen=True, slots=True)
class ImuSetup:
    """What the VIO stage needs beyond the camera: the IMU's noise (Kalibr densities), the camera pose
    in the IMU body frame, and the wheel odometry of a ground robot (forward = body x), if any."""

    noise: ImuNoise
    T_body_cam: SE3
    wheel: WheelData | None = None


@dataclass(frozen=True, slots=True)
class VoAnchor:
    """How a VO segment's frame maps into the VIO world: ``p_world = scale R_world_vo p_vo``."""

    segment: int
    scale: float
    R_world_vo: F64


@dataclass
class StaticStart:
    """The VIO stage's static start: the first frame's tracks, the decision and its result;
    ``still_px``: the median track motion since the first frame below which the camera stood
    still (:data:`amrvio.estimator.initializer.STILL_MRAD` in this camera's pixels)."""

    still_px: float
    ids: I64 | None = None
    uv: F64 | None = None
    decided: bool = False
    result: StaticInitResult | None = None


@dataclass
class BodyTrack:
    """Per frame index: the body pose ``T_world_body`` (4x4) the stage gives it, and frame times;
    the frames bridged since the last state (corrected by the next update, :meth:`_close_gap`);
    whether the newest smoothed pose passed its consistency checks, how many updates in a row
    the solver failed, since when the scale or bias-drift checks have been failing, and how the
    running estimate was initialised (``VioReport.init_kind``)."""

    poses: PoseBook = field(default_factory=PoseBook)
    index_of: dict[int, int] = field(default_factory=dict)
    bridged: set[int] = field(default_factory=set)
    anchored: dict[int, list[tuple[int, F64]]] = field(default_factory=dict)  # keyframe -> (frame, T_kf_frame)
    gap: list[tuple[int, int]] = field(default_factory=list)  # (index, t_ns) bridged since the last state
    last_state_ns: int | None = None  # time of the newest frame that got a state (an update or a start)
    closing: tuple[int, int, F64] | None = None  # (index, t_ns, IMU prediction) of the update to come
    consistent: bool = False  # the newest smoothed pose passed the consistency checks
    solver_failures: int = 0  # consecutive updates the solver failed
    drift_failing_since_ns: int | None = None  # the scale or bias checks fail from then on
    init_kind: str = ""

    def set(self, index: int, t_ns: int, T_world_body: SE3, bridged: bool = False,
            predicted: SE3 | None = None) -> None:
        """The pose of frame ``index``: ``bridged``, the IMU's prediction; otherwise a state, of an
        update (``predicted``: the IMU's prediction of the same frame from the newest state before
        it; :meth:`update` follows) or of a start."""
        self.index_of[t_ns] = index
        self.poses[index] = T_world_body.matrix()
        if bridged:
            self.bridged.add(index)
            self.gap.append((index, t_ns))
        elif predicted is None or not self.gap:  # nothing bridged since the last state: nothing to close
            self.gap.clear()
            self.last_state_ns = t_ns
        else:
            self.closing = (index, t_ns, predicted.matrix())

    def _close_gap(self, closing: tuple[int, int, F64], before: dict[int, F64]) -> None:
        """Spread the update's correction of the IMU prediction (``closing``: the updated frame's
        index, time and prediction) over the bridged frames since the last state, linearly in time
        (``before``: the anchors' poses before the update). The prediction through a gap drifts
        from nothing at its start to what the update measures at its end; left alone, the bridged
        frames kept all of that drift and none of the update. A bridged frame at the fraction w of
        the gap moves by w of the correction in position and turns by w of it in rotation, after
        moving with its keyframe (which the update may move too; the prediction goes with it)."""
        index, t_ns, T_pred = closing
        t0, gap = self.last_state_ns, list(self.gap)
        self.gap.clear()
        self.last_state_ns = t_ns
        if t0 is None or t_ns <= t0:
            return
        anchor = next((kf for kf, frames in self.anchored.items() if any(j == gap[-1][0] for j, _ in frames)), None)
        if anchor is not None and anchor in before:
            T_pred = self.poses[anchor] @ se3_matrix_inverse(before[anchor]) @ T_pred
        T_upd = self.poses[index]
        dp = T_upd[:3, 3] - T_pred[:3, 3]
        dw = so3_log(T_upd[:3, :3] @ T_pred[:3, :3].T)
        moved: dict[int, F64] = {}
        for i, t in gap:
            w = (t - t0) / (t_ns - t0)
            T = self.poses[i].copy()
            T[:3, :3] = so3_exp(w * dw) @ T[:3, :3]
            T[:3, 3] = T[:3, 3] + w * dp
            self.poses[i] = moved[i] = T
        for kf, frames in self.anchored.items():  # they move with their keyframe from the new pose on
            inv = se3_matrix_inverse(self.poses[kf])
            frames[:] = [(j, inv @ moved[j] if j in moved else rel) for j, rel in frames]

    def restart_due(self, checks: ConsistencyReport, after_s: float | None) -> bool:
        """Whether the checks of a keyframe re-initialise the smoother (``after_s`` None: never).
        A failed state-jump, bias-magnitude or reprojection check does at once (a wrong
        association, map or IMU state, now). The scale and bias-drift checks judge the last
        ``CheckConfig.window_s``; they do once they have failed on every keyframe for
        ``after_s`` (``VioStageConfig.reinit_after_s``): a restart throws away what the
        smoother's prior holds of the scale, and the short excursions these checks also catch
        correct themselves."""
        if checks.ok or after_s is None:
            self.drift_failing_since_ns = None
            return False
        if {c.value for c in checks.failed} - {"scale", "bias_drift"}:
            self.drift_failing_since_ns = None
            return True
        if self.drift_failing_since_ns is None:
            self.drift_failing_since_ns = checks.t_ns
        if (checks.t_ns - self.drift_failing_since_ns) * 1e-9 < after_s:
            return False
        self.drift_failing_since_ns = None
        return True

    def update(self, states: tuple[tuple[InertialState, bool], ...], newest: int | None = None) -> None:
        """The smoother's newer estimates of the frames still in its window (``states``, oldest
        first, each with whether it is a keyframe), and of the frames that left it with a
        keyframe still in it as their anchor.

        A frame that is not a keyframe (``newest``: the frame just given, or bridged) has no state
        after the next update; its pose is then kept relative to the newest keyframe of the window,
        and moves with that keyframe's later estimates. Held in the world instead, it kept the
        window's position and yaw of its own time, which later updates move (they are not
        observable): on forward-stop-turn, the poses of non-keyframes were 4-5 cm from those of
        their neighbouring keyframes in the final trajectory."""
        before = {kf: self.poses[kf].copy() for kf in self.anchored} if self.closing is not None else {}
        in_window: set[int] = set()
        keyframe: int | None = None
        newest_is_kf = False
        if states:  # the frame times the window no longer holds are not looked up again
            for t in [t for t in self.index_of if t < states[0][0].t_ns]:
                del self.index_of[t]
        for st, is_kf in states:
            i = self.index_of.get(st.t_ns)
            if i is not None:
                self.poses[i] = st.T_world_body.matrix()
                in_window.add(i)
                if i == newest:
                    newest_is_kf = is_kf
                elif is_kf:
                    keyframe = i
        if newest is not None and keyframe is not None and not newest_is_kf:
            rel = se3_matrix_inverse(self.poses[keyframe]) @ self.poses[newest]
            self.anchored.setdefault(keyframe, []).append((newest, rel))
        for kf in list(self.anchored):
            if kf not in in_window:  # marginalised: its frames' poses are final
                del self.anchored[kf]
                continue
            for j, rel in self.anchored[kf]:
                if j not in in_window:
                    self.poses[j] = self.poses[kf] @ rel
        closing, self.closing = self.closing, None
        if closing is not None and closing[0] == newest:
            self._close_gap(closing, before)


class VioPhase(Enum):
    """Where the visual-inertial stage is at a frame.

    VO: not initialised yet (the pose is the VO's, up to scale); VIO: the smoother's estimate of a
    frame given to it; BRIDGED: an IMU prediction for a frame the smoother did not get (blurred,
    dropped, lost or repeated); NO_IMU: the IMU does not cover the frame."""

    VO = "vo"
    VIO = "vio"
    BRIDGED = "bridged"
    NO_IMU = "no_imu"


@dataclass(frozen=True, slots=True, eq=False)
class VioReport:
    """The stage's report of one frame. ``estimate``: the body state (None before the
    initialisation); ``keyframe``: the smoother kept the frame as a keyframe; ``vi_init``: the
    dynamic initialisation attempted at this frame (None when none was); ``static``: the static
    initialisation decided at this frame; ``last_init``: the latest dynamic attempt (carried from
    frame to frame, for the health record); ``checks``: the consistency checks of the update;
    ``init_kind``: how the running estimate was initialised ("static", "dynamic", "reinit" or "");
    ``zero_velocity``: the standstill verdict on the frame (None: not judged, the smoother was
    not running or the frame was bridged); when ``still``, the update had ``v = 0`` in it."""

    phase: VioPhase
    estimate: VioEstimate | None = None
    keyframe: bool = False
    vi_init: ViInitResult | None = None
    static: StaticInitResult | None = None
    last_init: ViInitResult | None = None
    checks: ConsistencyReport | None = None
    init_kind: str = ""
    zero_velocity: ZeroVelocity | None = None

    @property
    def bridged(self) -> bool:
        return self.phase is VioPhase.BRIDGED

    def health_fields(self) -> dict[str, str]:
        """The ``vio_*`` / ``vi_init_*`` columns of health.csv (see :data:`VIO_COLUMNS`); empty
        where not known."""
        est = self.estimate
        st = est.state if est is not None and est.ok else None
        out = dict.fromkeys(VIO_COLUMNS, "")
        out["vio_phase"] = self.phase.value
        out["vio_init_kind"] = self.init_kind
        if st is not None and est is not None:
            v = np.asarray(st.v_world_m_s)
            out.update(vio_vx_m_s=_num(v[0], ".4f"), vio_vy_m_s=_num(v[1], ".4f"),
                       vio_vz_m_s=_num(v[2], ".4f"), vio_speed_m_s=_num(float(np.linalg.norm(v)), ".4f"),
                       vio_gyro_bias_norm_rad_s=_num(float(np.linalg.norm(st.bias.gyro_rad_s)), ".6f"),
                       vio_accel_bias_norm_m_s2=_num(float(np.linalg.norm(st.bias.accel_m_s2)), ".5f"))
            if est.position_sigma_m is not None:
                out["vio_position_sigma_m"] = _num(float(np.linalg.norm(est.position_sigma_m)), ".5f")
            if est.velocity_sigma_m_s is not None:
                out["vio_velocity_sigma_m_s"] = _num(float(np.linalg.norm(est.velocity_sigma_m_s)), ".5f")
        if self.checks is not None:
            out["vio_checks"] = self.checks.summary()
        zv = self.zero_velocity
        if zv is not None and zv.judged:
            out["vio_zero_velocity"] = "1" if zv.still else "0"
            out["vio_zero_velocity_flow_px"] = _num(zv.flow_px, ".3f")
        if self.static is not None:
            out["vio_static_init"] = self.static.status.value
        init = self.last_init
        if init is not None:
            f = init.health_fields()
            out["vi_init_status"] = str(f["vi_init_status"])
            for key in ("vi_init_scale", "vi_init_scale_std", "vi_init_gravity_norm_residual_m_s2",
                        "vi_init_gravity_std_deg"):
                val = f[key]
                out[key] = _num(float(val), ".5f") if isinstance(val, float) else ""
        return out


VIO_COLUMNS = ["vio_phase", "vio_init_kind", "vio_vx_m_s", "vio_vy_m_s", "vio_vz_m_s", "vio_speed_m_s",
               "vio_gyro_bias_norm_rad_s", "vio_accel_bias_norm_m_s2", "vio_position_sigma_m",
               "vio_velocity_sigma_m_s", "vio_checks", "vio_zero_velocity", "vio_zero_velocity_flow_px",
               "vio_static_init", "vi_init_status", "vi_init_scale",
               "vi_init_scale_std", "vi_init_gravity_norm_residual_m_s2", "vi_init_gravity_std_deg"]
"""The visual-inertial columns of health.csv: phase, how it was initialised, velocity (world, m/s),
bias norms, position and velocity sigmas (norm of the per-axis values), the consistency checks,
the zero-velocity verdict (1: the update had v = 0 in it; 0: judged moving; empty: not judged)
and the median track flow it judged on, the static initialisation's verdict, and the latest
dynamic initialisation's status, scale, scale std, gravity-norm residual and gravity-direction
std."""


def _num(v: float, fmt: str) -> str:
    return format(v, fmt) if math.isfinite(v) else ""


__all__ = ["UNTRACKED", "VIO_COLUMNS", "BodyTrack", "DynamicInitConfig", "ImuSetup", "StaticStart",
           "VioFrameInput", "VioPhase", "VioReport", "VioStageConfig", "VoAnchor", "vio_input"]
