"""``simulate(config, out_dir)``: motion -> IMU, wheel odometry, rendered frames -> ASL folder.

Frames are stamped at mid-exposure: frame k has stamp t_k = (k + 1/2) / fps (motion time) and
integrates the scene over [t_k - T_k/2, t_k + T_k/2]. Ground truth (T_world_body, velocity and the
true IMU biases) is written at the IMU stamps. Replay keeps the source stamps and world frame; the
renderer sees the trajectory shifted horizontally into the scene (``T_scene_world`` in
sim_config.yaml). Lens black-outs (``blackouts``, amrvio.sim.blackout) darken the frames exposed
while the lens is covered; everything else goes on, and sim_config.yaml lists the dark frames
(``derived.blackouts``).
"""

from __future__ import annotations

import dataclasses
import math
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ConfigError
from amrvio.sim.blackout import Blackout, frames_touched, parse_blackouts
from amrvio.sim.exposure_control import (
    AutoExposure,
    ExposureLimits,
    parse_ev_steps,
    scripted_exposures,
)
from amrvio.sim.motion import (
    MOTION_KINDS,
    Motion,
    MotionLayout,
    default_T_body_cam,
    make_motion,
    parse_blur_bursts,
)
from amrvio.sim.scene import SCENE_NAMES
from amrvio.sim.wheel import SlipEpisode
from amrvio.types.camera import CameraModel
from amrvio.types.lie import SE3, SO3
from amrvio.types.sensors import ImuData, ImuNoise

F64 = NDArray[np.float64]

SCENES: tuple[str, ...] = SCENE_NAMES
MOTIONS: tuple[str, ...] = (*MOTION_KINDS, "replay")
# EuRoC cam0 radial-tangential coefficients (k1, k2, p1, p2), used for camera_model="radtan".
EUROC_RADTAN = (-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05)
SIM_OUTPUTS = ("mav0", "times.txt", "pcalib.txt", "vignette.png", "wheel_odometry.csv",
               "sim_frames.csv", "sim_config.yaml")

Progress = Callable[[int, int], None]

SIM_BOUNDS: dict[str, tuple[float, float]] = {
    "seconds": (0.05, 3600.0),
    "seed": (0, 2**32 - 1),
    "imu_rate_hz": (1.0, 10_000.0),
    "side_px": (16, 4096),
    "replay_start_s": (0.0, 1e6),
    "replay_smoothing": (0.0, 1e6),
}
"""Closed ranges of the numeric options (``amrvio simulate --help`` states them)."""
MAX_PIXELS = 4096 * 3072
"""Largest image (pixels) the simulator renders."""
MAX_FRAMES = 100_000
"""Most frames one simulation renders (--seconds x --fps)."""
MAX_ABS_EV = 10.0
"""Largest scripted exposure step, in EV (a factor of 1024)."""
MAX_BURST_RAD_S = 30.0
"""Largest blur-burst yaw rate (rad/s, about 1700 deg/s: beyond a MEMS gyro's range)."""


@dataclass(frozen=True, slots=True)
class SimConfig:
    """Every parameter of a simulation run (recorded in sim_config.yaml).

    Camera: ``width`` x ``height`` at ``fps``, focal 0.61 * width (EuRoC-like field of view),
    ``camera_model`` "pinhole" or "radtan" (EuRoC coefficients); ``analog_gain`` multiplies the
    collected signal (and its shot noise) before the response, ``sensor_noise`` toggles shot and
    read noise, ``response_gamma`` shapes the response curve (1 = linear) and ``vignette_v1`` the
    radial fall-off V = 1 + v1 r^2 (amrvio.sim.image_formation.SensorModel). Exposure:
    ``exposure_ms`` base, optional ``ev_steps`` ("t:ev,..." relative steps) or ``auto_exposure``.
    ``blur_bursts``: "t0:dur:omega,..." fast yaw oscillations added to the motion. ``blackouts``:
    "t0:dur,..." time ranges with the lens covered (amrvio.sim.blackout). ``wheel_slips``:
    "t0:dur:slip,...". Replay: ``trajectory`` (EuRoC CSV or TUM), optional ``imu_csv`` (EuRoC imu0
    layout, used instead of the synthetic IMU) and ``cam_extrinsic`` (a sensor.yaml with T_BS).
    """

    scene: str = "corridor"
    motion: str = "forward-stop-turn"
    seconds: float = 10.0
    seed: int = 0
    fps: float = 20.0
    width: int = 752
    height: int = 480
    camera_model: str = "pinhole"
    camera_pitch_deg: float = 10.0
    imu_rate_hz: float = 200.0
    imu_noise: bool = True
    initial_gyro_bias_sigma: float = 0.005
    initial_accel_bias_sigma: float = 0.05
    blur: bool = True
    max_subframe_px: float = 0.5
    exposure_ms: float = 12.0
    analog_gain: float = 1.0
    sensor_noise: bool = True
    response_gamma: float = 1.0
    vignette_v1: float = -0.25
    ev_steps: str = ""
    auto_exposure: bool = False
    blur_bursts: str = ""
    blackouts: str = ""
    wheel_rate_hz: float = 50.0
    wheel_scale_error: float = 0.02
    wheel_slips: str = ""
    trajectory: str | None = None
    imu_csv: str | None = None
    cam_extrinsic: str | None = None
    replay_start_s: float = 0.0
    replay_smoothing: float = 0.0
    start_ns: int = 1_000_000_000

    def __post_init__(self) -> None:
        if self.scene not in SCENES:
            raise ConfigError(f"unknown scene {self.scene!r}; choose one of {', '.join(SCENES)}")
        if self.motion not in MOTIONS:
            raise ConfigError(f"unknown motion {self.motion!r}; choose one of {', '.join(MOTIONS)}")
        if self.motion == "replay" and not self.trajectory:
            raise ConfigError("--motion replay needs --trajectory GT_FILE (EuRoC CSV or TUM)")
        if self.motion != "replay" and (self.trajectory or self.imu_csv):
            raise ConfigError("--trajectory and --imu only apply to --motion replay")
        if not (math.isfinite(self.seconds) and self.seconds > 0):
            raise ConfigError(f"--seconds must be > 0, got {self.seconds}")
        if not (math.isfinite(self.fps) and 0 < self.fps <= 1000):
            raise ConfigError(f"--fps must be in (0, 1000], got {self.fps}")
        if self.width < 16 or self.height < 16:
            raise ConfigError(f"--resolution must be at least 16x16, got {self.width}x{self.height}")
        if self.camera_model not in ("pinhole", "radtan"):
            raise ConfigError(f"camera model must be pinhole or radtan, got {self.camera_model!r}")
        if not (math.isfinite(self.exposure_ms) and self.exposure_ms > 0):
            raise ConfigError(f"--exposure-ms must be > 0, got {self.exposure_ms}")
        if self.exposure_ms * 1e-3 > 0.9 / self.fps:
            raise ConfigError(
                f"--exposure-ms {self.exposure_ms:g} does not fit in the frame period "
                f"{1e3 / self.fps:.2f} ms (max 90 %)"
            )
        if not (math.isfinite(self.analog_gain) and 0.0 < self.analog_gain <= 64.0):
            raise ConfigError(f"--gain (analog gain) must be in (0, 64], got {self.analog_gain}")
        if not (0.2 <= self.response_gamma <= 5.0):
            raise ConfigError(f"--response-gamma must be in [0.2, 5], got {self.response_gamma}")
        if not (-1.0 < self.vignette_v1 <= 0.0):
            raise ConfigError(f"--vignette-v1 must be in (-1, 0], got {self.vignette_v1}")
        if self.replay_smoothing < 0:
            raise ConfigError(f"--replay-smoothing must be >= 0, got {self.replay_smoothing}")
        if self.ev_steps and self.auto_exposure:
            raise ConfigError("use either --ev-steps or --auto-exposure, not both")
        if not (math.isfinite(self.imu_rate_hz) and math.isfinite(self.wheel_rate_hz)
                and self.imu_rate_hz > 0 and self.wheel_rate_hz > 0):
            raise ConfigError("IMU and wheel rates must be finite and > 0 Hz")
        if self.seed < 0:
            raise ConfigError(f"--seed must be >= 0, got {self.seed}")
        for option, value, (lo, hi) in (
            ("--seconds", self.seconds, SIM_BOUNDS["seconds"]),
            ("--seed", self.seed, SIM_BOUNDS["seed"]),
            ("--imu-rate", self.imu_rate_hz, SIM_BOUNDS["imu_rate_hz"]),
            ("wheel rate", self.wheel_rate_hz, SIM_BOUNDS["imu_rate_hz"]),
            ("--resolution width", self.width, SIM_BOUNDS["side_px"]),
            ("--resolution height", self.height, SIM_BOUNDS["side_px"]),
            ("--replay-start", self.replay_start_s, SIM_BOUNDS["replay_start_s"]),
            ("--replay-smoothing", self.replay_smoothing, SIM_BOUNDS["replay_smoothing"]),
        ):
            if not ((isinstance(value, int) or math.isfinite(value)) and lo <= value <= hi):
                raise ConfigError(f"{option} must be in [{lo:g}, {hi:g}], got {value}")
        if self.width * self.height > MAX_PIXELS:
            raise ConfigError(f"--resolution {self.width}x{self.height}: at most {MAX_PIXELS} "
                              "pixels (e.g. 2048x1536)")
        n_frames = self.seconds * self.fps
        if n_frames > MAX_FRAMES:
            raise ConfigError(f"--seconds {self.seconds:g} at --fps {self.fps:g} gives "
                              f"{n_frames:.0f} frames; at most {MAX_FRAMES}")
        for t, ev in parse_ev_steps(self.ev_steps):
            if t > self.seconds or abs(ev) > MAX_ABS_EV:
                raise ConfigError(f"--ev-steps item {t:g}:{ev:g}: need a time in [0, --seconds] "
                                  f"and |EV| <= {MAX_ABS_EV:g}")
        for b in parse_blur_bursts(self.blur_bursts):
            if b.t0_s < 0 or b.t0_s > self.seconds or b.dur_s > self.seconds \
                    or abs(b.omega_rad_s) > MAX_BURST_RAD_S:
                raise ConfigError(f"--blur-bursts item {b.t0_s:g}:{b.dur_s:g}:{b.omega_rad_s:g}: "
                                  "need t0 in [0, --seconds], dur <= --seconds and |omega| <= "
                                  f"{MAX_BURST_RAD_S:g} rad/s")
        parse_blackouts(self.blackouts, self.seconds)
        for sl in parse_slips(self.wheel_slips):
            if sl.t0_s < 0 or sl.t0_s > self.seconds or sl.dur_s > self.seconds \
                    or not -1.0 <= sl.slip <= 10.0:
                raise ConfigError(f"--wheel-slips item {sl.t0_s:g}:{sl.dur_s:g}:{sl.slip:g}: "
                                  "need t0 in [0, --seconds], dur <= --seconds and slip in "
                                  "[-1, 10]")


@dataclass(frozen=True, slots=True)
class SimSummary:
    out_dir: Path
    n_frames: int
    n_imu: int
    n_wheel: int
    duration_s: float
    path_length_m: float
    max_smear_px: float
    exposure_ms_min: float
    exposure_ms_max: float
    imu_source: str
    dark_frames: int = 0  # frames exposed entirely while the lens was covered (--blackout)


def parse_slips(spec: str) -> tuple[SlipEpisode, ...]:
    """``"t0:dur:slip,..."`` -> SlipEpisode tuple. Raises ConfigError."""
    out: list[SlipEpisode] = []
    for item in (s.strip() for s in spec.split(",")):
        if not item:
            continue
        try:
            t0, dur, slip = (float(v) for v in item.split(":"))
        except ValueError:
            raise ConfigError(f"wheel slip item {item!r} is not 't0:dur:slip'") from None
        if dur <= 0 or not all(math.isfinite(v) for v in (t0, dur, slip)):
            raise ConfigError(f"wheel slip item {item!r}: need finite values and dur > 0")
        out.append(SlipEpisode(t0, dur, slip))
    return tuple(out)


def make_camera(config: SimConfig) -> CameraModel:
    from amrvio.types.camera import camera_from_params

    w, h = config.width, config.height
    f = 0.61 * w  # EuRoC cam0: 458.654 px at 752 px width
    intr = [f, f, w / 2.0, h / 2.0]
    if config.camera_model == "radtan":
        return camera_from_params("pinhole", "radtan", intr, EUROC_RADTAN, [w, h])
    return camera_from_params("pinhole", "none", intr, [], [w, h])


def layout_for_scene(scene: Any) -> MotionLayout:
    """The motion layout inside a Scene's free floor area (room: a square loop).

    The free space to the left, right and behind of the start is measured across and along the
    start heading inside the scene's free rectangle (every scene's start heading is axis-aligned).
    """
    lo = np.asarray(scene.free_xy_min, dtype=np.float64)
    hi = np.asarray(scene.free_xy_max, dtype=np.float64)
    if scene.name == "room":
        side = float(min(hi - lo)) - 1.0
        start = lo + 0.5
        heading, length, loop = 0.0, side, side
    else:
        start = np.asarray(scene.start_position_m, dtype=np.float64)[:2]
        heading, length, loop = float(scene.start_yaw_rad), float(scene.drive_length_m), None
    corners = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]]) - start
    fwd = np.array([math.cos(heading), math.sin(heading)])
    left = np.array([-fwd[1], fwd[0]])
    return MotionLayout(start_xy=(float(start[0]), float(start[1])), heading_rad=heading,
                        free_length_m=length, loop_side_m=loop,
                        free_left_m=max(0.0, float((corners @ left).max())),
                        free_right_m=max(0.0, float(-(corners @ left).min())),
                        free_behind_m=max(0.0, float(-(corners @ fwd).min())))


@dataclass(frozen=True, slots=True, eq=False)
class _Sources:
    motion: Motion
    imu: ImuData
    imu_t_s: F64
    gyro_bias: F64
    accel_bias: F64
    imu_noise: ImuNoise
    imu_source: str
    stamp0_ns: int  # the stamp of motion time 0
    T_body_cam: SE3


def _synthetic_imu_sources(config: SimConfig, motion: Motion, rngs: list[np.random.Generator],
                           stamp0_ns: int, T_body_cam: SE3) -> _Sources:
    """Synthetic IMU from the motion's exact derivatives: with ``config.imu_noise`` EuRoC ADIS16448
    white noise, bias random walk and random initial biases (rngs[0]: biases, rngs[1]: noise)."""
    from amrvio.sim.imu_synth import synthesize_imu

    noise = dataclasses.replace(ImuNoise.euroc_adis16448(), rate_hz=config.imu_rate_hz)
    if config.imu_noise:
        bg0 = rngs[0].standard_normal(3) * config.initial_gyro_bias_sigma
        ba0 = rngs[0].standard_normal(3) * config.initial_accel_bias_sigma
        syn = synthesize_imu(motion, config.imu_rate_hz, noise, rngs[1], stamp0_ns, bg0, ba0)
    else:
        syn = synthesize_imu(motion, config.imu_rate_hz, None, None, stamp0_ns)
    return _Sources(motion, syn.imu, syn.t_s, syn.gyro_bias, syn.accel_bias, noise,
                    "synthetic" if config.imu_noise else "synthetic-exact", stamp0_ns, T_body_cam)


def _synthetic_sources(config: SimConfig, scene: Any, rngs: list[np.random.Generator]) -> _Sources:
    motion = make_motion(config.motion, config.seconds, layout_for_scene(scene), config.seed,
                         parse_blur_bursts(config.blur_bursts))
    return _synthetic_imu_sources(config, motion, rngs, config.start_ns,
                                  default_T_body_cam(config.camera_pitch_deg))


def _replay_sources(config: SimConfig, rngs: list[np.random.Generator]) -> _Sources:
    from amrvio.io.base import read_imu_csv
    from amrvio.io.calib import read_euroc_imu, read_euroc_sensor_T_BS
    from amrvio.sim.replay import load_groundtruth, make_replay_motion

    gt_path = Path(str(config.trajectory))
    ns, p, q, bg, ba = load_groundtruth(gt_path)
    try:
        motion = make_replay_motion(ns, p, q, config.replay_start_s, config.seconds,
                                    config.replay_smoothing, bg, ba)
    except ConfigError as err:  # the message names no file: name the one it is about
        raise ConfigError(f"--trajectory {gt_path}: {err}") from None
    # extrinsic: explicit file, else the source's cam0/sensor.yaml (EuRoC layout), else default
    T_body_cam = default_T_body_cam(config.camera_pitch_deg)
    ext = (Path(config.cam_extrinsic) if config.cam_extrinsic
           else gt_path.parent.parent / "cam0" / "sensor.yaml")
    if ext.is_file():
        T_body_cam = read_euroc_sensor_T_BS(ext)
    elif config.cam_extrinsic:
        raise ConfigError(f"{ext}: camera extrinsic file does not exist")
    if config.imu_csv:
        imu_path = Path(config.imu_csv)
        full = read_imu_csv(imu_path)
        imu = full.window(motion.t0_ns, motion.t0_ns + round(motion.duration_s * 1e9))
        if len(imu) < 2:
            raise ConfigError(f"{imu_path}: no IMU samples inside the replayed window")
        t = (imu.stamps_ns - motion.t0_ns).astype(np.float64) * 1e-9
        noise_yaml = imu_path.parent / "sensor.yaml"
        noise = read_euroc_imu(noise_yaml) if noise_yaml.is_file() else ImuNoise.euroc_adis16448()
        gb = motion.gyro_bias_at(t)
        ab = motion.accel_bias_at(t)
        zeros = np.zeros((t.shape[0], 3))
        return _Sources(motion, imu, t, zeros if gb is None else gb, zeros if ab is None else ab,
                        noise, "recorded", motion.t0_ns, T_body_cam)
    return _synthetic_imu_sources(config, motion, rngs, motion.t0_ns, T_body_cam)


def _scene_offset(motion: Motion, scene: Any) -> SE3:
    """Horizontal shift that centres a replayed path in the scene's free floor area."""
    t = np.linspace(0.0, motion.duration_s, 200)
    p = motion.states(t).p_world
    centre = 0.5 * (p[:, :2].min(axis=0) + p[:, :2].max(axis=0))
    target = 0.5 * (np.asarray(scene.free_xy_min) + np.asarray(scene.free_xy_max))
    return SE3(SO3.identity(), np.array([target[0] - centre[0], target[1] - centre[1], 0.0]))


def prepare_out_dir(out_dir: Path, force: bool) -> None:
    """Refuse a non-empty OUT unless ``force``; with ``force`` remove earlier simulator outputs."""
    if out_dir.exists() and not out_dir.is_dir():
        raise ConfigError(f"{out_dir}: output path exists and is not a folder")
    if out_dir.is_dir() and any(out_dir.iterdir()):
        if not force:
            raise ConfigError(f"{out_dir}: output folder is not empty; use --force to overwrite")
        for name in SIM_OUTPUTS:
            p = out_dir / name
            if p.is_dir():
                shutil.rmtree(p)
            elif p.exists():
                p.unlink()
    out_dir.mkdir(parents=True, exist_ok=True)


def _plain(x: Any) -> Any:
    """YAML-safe plain values (tuples -> lists, numpy -> float lists)."""
    if isinstance(x, dict):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if isinstance(x, np.ndarray):
        return _plain(x.tolist())
    if isinstance(x, (np.floating, float)):
        return float(x)
    if isinstance(x, (np.integer, int)) and not isinstance(x, bool):
        return int(x)
    if isinstance(x, Path):
        return str(x)
    return x


def _blackout_records(blackouts: tuple[Blackout, ...], t_starts: list[float], exposures: list[float],
                      stamps: list[int]) -> list[dict[str, Any]]:
    """sim_config.yaml ``derived.blackouts``: per black-out its range, the first and last frame
    exposed entirely inside it (index and stamp; empty when none) and the partly covered frames."""
    out: list[dict[str, Any]] = []
    for b in blackouts:
        f = frames_touched(b, t_starts, exposures)
        dark = [f.dark[0], f.dark[-1]] if f.dark else []
        out.append({"t0_s": b.t0_s, "dur_s": b.dur_s, "dark_frames": dark,
                    "dark_stamps_ns": [stamps[k] for k in dark],
                    "partly_covered_frames": list(f.partial)})
    return out


def simulate(config: SimConfig, out_dir: Path, progress: Progress | None = None,
             force: bool = False) -> SimSummary:
    """Run the simulation and write the sequence to ``out_dir`` (see amrvio.sim.writer)."""
    from amrvio.photometric.model import RadialVignette
    from amrvio.sim.image_formation import CameraResponse, SensorModel, render_frame
    from amrvio.sim.render import SceneRenderer
    from amrvio.sim.scene import make_scene
    from amrvio.sim.wheel import WheelConfig, synthesize_wheel, write_wheel_csv
    from amrvio.sim.writer import FrameRecord, SequenceWriter

    out_dir = Path(out_dir)
    prepare_out_dir(out_dir, force)
    # independent streams: biases, IMU noise, wheel noise, image noise
    rngs = [np.random.default_rng(s) for s in np.random.SeedSequence(config.seed).spawn(4)]
    scene = make_scene(config.scene, config.seed)
    camera = make_camera(config)
    if config.motion == "replay":
        src = _replay_sources(config, rngs)
        T_scene_world = _scene_offset(src.motion, scene)
    else:
        src = _synthetic_sources(config, scene, rngs)
        T_scene_world = SE3.identity()
    motion = src.motion
    T_body_cam = src.T_body_cam

    writer = SequenceWriter(out_dir)
    # ground truth at the IMU stamps
    gt = motion.states(src.imu_t_s)
    # The densities in imu0/sensor.yaml stay the nominal ADIS16448 values even for exact data
    # (--imu-noise off): an estimator needs nonzero noise to weight its factors. The comment line
    # and sim_config.yaml (imu_source) say whether the samples carry that noise.
    imu_comment = {"synthetic": "amrvio simulated IMU (noise and bias random walk at these densities)",
                   "synthetic-exact": "amrvio simulated IMU, EXACT data (--imu-noise off): the "
                   "densities are nominal values for the estimator, the samples carry no noise",
                   "recorded": "amrvio replay: recorded IMU, densities of the source"}[src.imu_source]
    writer.write_imu(src.imu, src.imu_noise, imu_comment)
    writer.write_groundtruth(src.imu.stamps_ns, gt.R_world_body, gt.p_world, gt.v_world,
                             src.gyro_bias, src.accel_bias)
    wheel_cfg = WheelConfig(rate_hz=config.wheel_rate_hz, scale_error=config.wheel_scale_error,
                            slips=parse_slips(config.wheel_slips))
    wheel = synthesize_wheel(motion, wheel_cfg, rngs[2], src.stamp0_ns)
    write_wheel_csv(out_dir / "wheel_odometry.csv", wheel)

    # frames: stamps at mid-exposure
    n_frames = int(math.floor(motion.duration_s * config.fps + 1e-9))
    t_frames = (np.arange(n_frames) + 0.5) / config.fps
    stamps = [src.stamp0_ns + int(round(t * 1e9)) for t in t_frames]
    limits = ExposureLimits(frame_period_s=1.0 / config.fps)
    base = config.exposure_ms * 1e-3
    planned = scripted_exposures(t_frames, base, parse_ev_steps(config.ev_steps), limits)
    ae = AutoExposure() if config.auto_exposure else None
    sensor = SensorModel(gain=config.analog_gain, response=CameraResponse(config.response_gamma),
                         vignette=RadialVignette(config.vignette_v1), noise=config.sensor_noise)
    renderer = SceneRenderer(scene, camera)

    def pose_at(t: float) -> SE3:
        return T_scene_world @ motion.T_world_body(t) @ T_body_cam

    blackouts = parse_blackouts(config.blackouts, config.seconds)
    covered = [(b.t0_s, b.t1_s) for b in blackouts]
    exposures: list[float] = []
    t_starts: list[float] = []
    records: list[FrameRecord] = []
    max_smear = 0.0
    exposure = base
    for k in range(n_frames):
        if ae is None:
            exposure = float(planned[k])
        exposure = round(exposure * 1e6) / 1e6  # whole microseconds, as times.txt stores them
        t0 = float(t_frames[k]) - 0.5 * exposure
        frame = render_frame(renderer, pose_at, t0, exposure, sensor,
                             rngs[3] if config.sensor_noise else None, blur=config.blur,
                             max_subframe_px=config.max_subframe_px, lens_covered=covered)
        writer.write_frame(stamps[k], frame.image)
        exposures.append(exposure)
        t_starts.append(t0)
        records.append(FrameRecord(stamps[k], exposure, float(frame.smear_px_max),
                                   float(frame.smear_px_center), int(frame.n_subframes),
                                   float(frame.image.mean()), float(frame.open_fraction)))
        max_smear = max(max_smear, float(frame.smear_px_max))
        if ae is not None:
            exposure = ae.next_exposure(exposure, float(frame.image.mean()), limits)
        if progress is not None:
            progress(k + 1, n_frames)
    writer.finish_camera(camera, T_body_cam, config.fps, exposures)
    writer.write_frames(records)
    writer.write_photometric(sensor.response.inverse_lut(),
                             sensor.vignette.map(camera.height, camera.width))

    path_len = float(np.linalg.norm(np.diff(gt.p_world, axis=0), axis=1).sum())
    record: dict[str, Any] = {
        "config": _plain(dataclasses.asdict(config)),
        "derived": _plain({
            "camera": {"model": camera.distortion_model, "fx": camera.fx, "fy": camera.fy,
                       "cx": camera.cx, "cy": camera.cy, "distortion": list(camera.distortion),
                       "width": camera.width, "height": camera.height},
            "T_body_cam": T_body_cam.matrix(),
            "T_scene_world": T_scene_world.matrix(),
            "frame_stamp": "mid-exposure",
            "gravity_world_m_s2": [0.0, 0.0, -9.81],
            "imu_source": src.imu_source,
            "imu_noise": dataclasses.asdict(src.imu_noise),
            "initial_gyro_bias": src.gyro_bias[0],
            "initial_accel_bias": src.accel_bias[0],
            "stamp_of_motion_time_zero_ns": src.stamp0_ns,
            "sensor": repr(sensor),
            "n_frames": n_frames,
            "blackouts": _blackout_records(blackouts, t_starts, exposures, stamps),
        }),
    }
    writer.write_config(record)
    return SimSummary(out_dir, n_frames, len(src.imu), int(wheel.stamps_ns.shape[0]),
                      motion.duration_s, path_len, max_smear,
                      1e3 * min(exposures, default=0.0), 1e3 * max(exposures, default=0.0),
                      src.imu_source, sum(r.lens_open_fraction == 0.0 for r in records))
