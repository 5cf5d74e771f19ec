"""``amrvio simulate``: render a synthetic sequence with IMU, wheel odometry and ground truth."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from typing import Any

from amrvio.cli.args import bounded, interval

NAME = "simulate"
# amrvio.sim.simulate.SCENES and MOTIONS (kept here so that building the parser imports no
# simulator code; tests/sim/test_simulate.py checks that they agree)
SCENE_CHOICES = ("corridor", "warehouse", "room", "wall")
MOTION_CHOICES = ("forward-stop-turn", "constant-velocity", "rough-floor", "handheld", "wall-scan",
                  "start-in-turn", "turn-in-place", "replay")
HELP = "simulate a camera + IMU + wheel-odometry sequence with ground truth (ASL/EuRoC layout)"


# The ranges of amrvio.sim.simulate.SIM_BOUNDS, MAX_PIXELS (SimConfig checks them again; a test
# keeps the two equal). Kept here so that `amrvio --help` does not import the simulator.
OPTION_BOUNDS: dict[str, tuple[float, float]] = {
    "seconds": (0.05, 3600.0),
    "seed": (0, 2**32 - 1),
    "imu_rate_hz": (1.0, 10_000.0),
    "side_px": (16, 4096),
    "replay_start_s": (0.0, 1e6),
    "replay_smoothing": (0.0, 1e6),
}
MAX_PIXELS = 4096 * 3072


def _resolution(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"resolution must be WxH, e.g. 752x480, got {text[:40]!r}") from None
    lo, hi = OPTION_BOUNDS["side_px"]
    if not (lo <= w <= hi and lo <= h <= hi) or w * h > MAX_PIXELS:
        raise argparse.ArgumentTypeError(f"each side must be in [{lo:g}, {hi:g}] px and W x H at "
                                         f"most {MAX_PIXELS} pixels, got {text[:40]}")
    return w, h


def _in(key: str) -> tuple[Callable[[str], Any], str]:
    """(argparse type, range text) of an OPTION_BOUNDS entry."""
    lo, hi = OPTION_BOUNDS[key]
    return bounded(lo, hi, integer=key == "seed"), interval(lo, hi)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--scene", choices=SCENE_CHOICES, default="corridor",
                        help="corridor (2.4 m wide), warehouse (aisle between racks), room (8 x 8 m, "
                        "clutter near the walls), wall (one textured planar wall, 14 x 5 m)")
    parser.add_argument(
        "--motion",
        choices=MOTION_CHOICES,
        default="forward-stop-turn",
        help="forward-stop-turn: rest, drive, stop, turn in place (room: square loop); "
        "constant-velocity; rough-floor: vibration; handheld: walking, aggressive 6-DoF; "
        "wall-scan: hand-held 1.3-2.9 m in front of what lies ahead (for --scene wall); "
        "start-in-turn: robot moving (0.3 m/s, speeding up to 0.5) and turning at 0.4 rad/s from the "
        "first frame, the turn fading out after 2 s (corridor, warehouse: then straight; room: a "
        "loop of 90 deg corners); turn-in-place: robot driving at 0.5 m/s stops, turns 30 deg in "
        "place in 2 s and drives on; replay: follow --trajectory",
    )
    parser.add_argument("--trajectory", metavar="GT_FILE",
                        help="replay: ground truth to follow (EuRoC CSV or TUM)")
    parser.add_argument("--imu", metavar="IMU_CSV",
                        help="replay: recorded IMU (EuRoC imu0 CSV) used instead of synthetic IMU")
    parser.add_argument("--cam-extrinsic", metavar="SENSOR_YAML",
                        help="replay: sensor.yaml whose T_BS is the camera pose in the IMU frame")
    start_t, start_r = _in("replay_start_s")
    parser.add_argument("--replay-start", type=start_t, default=0.0, metavar="S",
                        help=f"replay: seconds after the first ground-truth pose, in {start_r}")
    smooth_t, smooth_r = _in("replay_smoothing")
    parser.add_argument("--replay-smoothing", type=smooth_t, default=0.0, metavar="LAM",
                        help="replay: smoothing-spline penalty on positions (0 = interpolate), "
                             f"in {smooth_r}")
    sec_t, sec_r = _in("seconds")
    parser.add_argument("--seconds", type=sec_t, default=10.0,
                        help=f"duration, in {sec_r} s (and at most 100000 frames)")
    seed_t, seed_r = _in("seed")
    parser.add_argument("--seed", type=seed_t, default=0, help=f"in {seed_r}")
    parser.add_argument("--imu-noise", choices=("on", "off"), default="on",
                        help="off: exact IMU samples and constant zero biases; imu0/sensor.yaml "
                        "still lists the nominal ADIS16448 densities (an estimator needs them) "
                        "and its comment says the data are exact")
    rate_t, rate_r = _in("imu_rate_hz")
    parser.add_argument("--imu-rate", type=rate_t, default=200.0, metavar="HZ",
                        help=f"IMU rate, in {rate_r} Hz")
    parser.add_argument("--blur", choices=("on", "off"), default="on")
    parser.add_argument("--exposure-ms", type=bounded(0.0, 1000.0, lo_open=True), default=12.0,
                        help="exposure time, in (0, 1000] ms and at most 90 %% of the frame "
                             "period")
    parser.add_argument("--gain", type=bounded(0.0, 64.0, lo_open=True), default=1.0,
                        help="analog gain applied to the collected signal before the response, "
                             "in (0, 64]")
    parser.add_argument("--sensor-noise", choices=("on", "off"), default="on",
                        help="shot and read noise of the image sensor")
    parser.add_argument("--ev-steps", default="", metavar="T:EV,...",
                        help='scripted exposure steps, e.g. "2:+1,5:-0.5" (EV = log2 exposure '
                             'ratio; T in [0, --seconds], |EV| <= 10)')
    parser.add_argument("--auto-exposure", action="store_true",
                        help="P-control of the mean intensity (rate-limited)")
    parser.add_argument("--response-gamma", type=bounded(0.2, 5.0), default=1.0,
                        help="camera response G(x) ~ x^(1/gamma) with a linear toe; 1 = linear; "
                             "in [0.2, 5]")
    parser.add_argument("--vignette-v1", type=bounded(-1.0, 0.0, lo_open=True), default=-0.25,
                        help="radial vignetting V = 1 + v1 r^2 (r = 1 at the image corner), "
                             "in (-1, 0]")
    parser.add_argument("--fps", type=bounded(0.0, 1000.0, lo_open=True), default=20.0,
                        help="frame rate, in (0, 1000] Hz")
    parser.add_argument("--resolution", type=_resolution, default=(752, 480), metavar="WxH",
                        help="image size; each side in [16, 4096] px, at most 4096x3072 pixels")
    parser.add_argument("--camera-model", choices=("pinhole", "radtan"), default="pinhole")
    parser.add_argument("--blur-bursts", default="", metavar="T0:DUR:OMEGA,...",
                        help="fast yaw oscillations (peak rad/s) added to the motion; T0 in "
                             "[0, --seconds], DUR in (0, --seconds], |OMEGA| <= 30 rad/s")
    parser.add_argument("--blackout", action="append", default=[], metavar="T0:DUR,...",
                        help="cover the lens over [T0, T0+DUR) seconds (repeatable or "
                        "comma-separated): frames exposed then are near-black (read noise only) "
                        "while the motion, IMU and wheel data go on; sim_config.yaml lists the dark "
                        "frames under derived.blackouts")
    parser.add_argument("--wheel-slips", default="", metavar="T0:DUR:SLIP,...",
                        help="wheel slip episodes; T0 in [0, --seconds], DUR in (0, --seconds], "
                             "SLIP in [-1, 10]")
    parser.add_argument("--out", required=True, metavar="DIR",
                        help="output folder, checked before any work; a non-empty one needs "
                             "--force")
    parser.add_argument("--force", action="store_true", help="overwrite a non-empty DIR")


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from tqdm import tqdm

    from amrvio.sim.simulate import SimConfig, simulate

    config = SimConfig(
        scene=args.scene,
        motion=args.motion,
        seconds=args.seconds,
        seed=args.seed,
        fps=args.fps,
        width=args.resolution[0],
        height=args.resolution[1],
        camera_model=args.camera_model,
        imu_rate_hz=args.imu_rate,
        imu_noise=args.imu_noise == "on",
        blur=args.blur == "on",
        exposure_ms=args.exposure_ms,
        analog_gain=args.gain,
        sensor_noise=args.sensor_noise == "on",
        response_gamma=args.response_gamma,
        vignette_v1=args.vignette_v1,
        ev_steps=args.ev_steps,
        auto_exposure=args.auto_exposure,
        blur_bursts=args.blur_bursts,
        blackouts=",".join(args.blackout),
        wheel_slips=args.wheel_slips,
        trajectory=args.trajectory,
        imu_csv=args.imu,
        cam_extrinsic=args.cam_extrinsic,
        replay_start_s=args.replay_start,
        replay_smoothing=args.replay_smoothing,
    )
    from amrvio.io.outdir import prepare_output_dir
    from amrvio.sim.simulate import SIM_OUTPUTS

    prepare_output_dir(Path(args.out), args.force, SIM_OUTPUTS)
    bar = tqdm(total=0, unit="frame", desc="simulate", file=sys.stderr,
               disable=not sys.stderr.isatty())

    def progress(done: int, total: int) -> None:
        bar.total = total
        bar.update(done - bar.n)

    try:
        summary = simulate(config, Path(args.out), progress=progress, force=args.force)
    finally:
        bar.close()
    print(
        f"wrote {summary.out_dir}: {summary.n_frames} frames, {summary.n_imu} IMU samples "
        f"({summary.imu_source}), {summary.n_wheel} wheel readings, {summary.duration_s:.2f} s, "
        f"path {summary.path_length_m:.2f} m, max smear {summary.max_smear_px:.1f} px, "
        f"exposure {summary.exposure_ms_min:.3f}-{summary.exposure_ms_max:.3f} ms"
        + (f", {summary.dark_frames} dark frames (lens covered)" if summary.dark_frames else "")
    )
    return 0
