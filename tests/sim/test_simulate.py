"""End-to-end simulator: determinism, read-back through open_dataset, exposure, wheel odometry."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from amrvio.errors import ConfigError
from amrvio.sim.exposure_control import (
    AutoExposure,
    ExposureLimits,
    parse_ev_steps,
    scripted_exposures,
)
from amrvio.sim.motion import MotionLayout, make_motion, parse_blur_bursts
from amrvio.sim.wheel import SlipEpisode, WheelConfig, synthesize_wheel, write_wheel_csv
from amrvio.sim.writer import ns_to_s_text


def _tree(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


# ------------------------------------------------------------------------------ exposure control


def test_parse_ev_steps() -> None:
    assert parse_ev_steps("2:+1, 1:-0.5") == ((1.0, -0.5), (2.0, 1.0))
    assert parse_ev_steps("") == ()
    for bad in ("2", "a:1", "1:2:3", "-1:1", "1:inf"):
        with pytest.raises(ConfigError):
            parse_ev_steps(bad)


def test_scripted_exposures_follow_ev_and_fit_the_frame_period() -> None:
    lim = ExposureLimits(frame_period_s=0.05)
    t = np.array([0.0, 0.99, 1.0, 2.5, 3.0])
    e = scripted_exposures(t, 0.008, ((1.0, 1.0), (2.0, -0.5), (3.0, 4.0)), lim)
    np.testing.assert_allclose(e[:4], [0.008, 0.008, 0.016, 0.016 * 2**-0.5])
    assert e[4] == pytest.approx(0.9 * 0.05)  # 0.008 * 2^4.5 = 181 ms clamped to 90 % of 50 ms


def test_auto_exposure_converges_with_limited_rate() -> None:
    ae = AutoExposure(target_dn=110.0, gain=0.5, max_ev_per_frame=0.25)
    lim = ExposureLimits(frame_period_s=0.05)
    e, k = 0.001, 20000.0  # linear sensor: mean = k * exposure (unsaturated)
    history = [e]
    for _ in range(60):
        e = ae.next_exposure(e, min(k * e, 255.0), lim)
        history.append(e)
    steps = np.abs(np.diff(np.log2(history)))
    assert steps.max() <= 0.25 + 1e-12
    assert k * e == pytest.approx(110.0, rel=0.01)


# ------------------------------------------------------------------------------ wheel odometry


def test_wheel_odometry_scale_noise_and_slip(tmp_path: Path) -> None:
    m = make_motion("forward-stop-turn", 20.0, MotionLayout(free_length_m=35.0))
    cfg = WheelConfig(rate_hz=50.0, scale_error=0.02, speed_noise_m_s=0.0, yaw_rate_noise_rad_s=0.0,
                      slips=(SlipEpisode(5.0, 1.0, 0.3),))
    w = synthesize_wheel(m, cfg, np.random.default_rng(0), start_ns=7)
    assert w.stamps_ns[0] == 7 and w.stamps_ns[1] - w.stamps_ns[0] == 20_000_000
    s = m.states((w.stamps_ns - 7) * 1e-9)
    speed = np.linalg.norm(s.v_world, axis=1)
    np.testing.assert_allclose(np.abs(w.v_forward_true_m_s), speed, atol=1e-12)  # no side slip
    np.testing.assert_allclose(w.yaw_rate_true_rad_s, s.omega_body[:, 2])
    ratio = np.where(w.slipping, 1.3, 1.0) * 1.02
    np.testing.assert_allclose(w.v_forward_m_s, ratio * w.v_forward_true_m_s, atol=1e-15)
    assert w.slipping.sum() == 51
    noisy = synthesize_wheel(m, WheelConfig(speed_noise_m_s=0.01), np.random.default_rng(0))
    resid = noisy.v_forward_m_s - 1.02 * noisy.v_forward_true_m_s
    assert 0.008 < resid.std() < 0.012
    path = tmp_path / "w.csv"
    write_wheel_csv(path, w)
    rows = path.read_text().splitlines()
    assert rows[0].startswith("timestamp_ns,v_forward_m_s,yaw_rate_rad_s")
    assert len(rows) == len(w.stamps_ns) + 1


def test_ns_to_s_text_is_exact() -> None:
    assert ns_to_s_text(1403715273262142976) == "1403715273.262142976"
    assert ns_to_s_text(5) == "0.000000005"


# ------------------------------------------------------------------------------ configuration


def test_config_errors() -> None:
    from amrvio.sim.simulate import SimConfig

    with pytest.raises(ConfigError):
        SimConfig(scene="moon")
    with pytest.raises(ConfigError):
        SimConfig(motion="replay")
    with pytest.raises(ConfigError, match="frame period"):
        SimConfig(fps=100.0, exposure_ms=20.0)
    with pytest.raises(ConfigError):
        SimConfig(ev_steps="1:1", auto_exposure=True)
    with pytest.raises(ConfigError):
        SimConfig(blur_bursts="1:2")
    with pytest.raises(ConfigError, match="seed"):
        SimConfig(seed=-3)
    with pytest.raises(ConfigError, match="rates"):
        SimConfig(imu_rate_hz=float("nan"))


def test_refuses_non_empty_out_dir(tmp_path: Path) -> None:
    from amrvio.sim.simulate import prepare_out_dir

    (tmp_path / "keep.txt").write_text("x")
    with pytest.raises(ConfigError, match="--force"):
        prepare_out_dir(tmp_path, force=False)
    (tmp_path / "times.txt").write_text("old")
    prepare_out_dir(tmp_path, force=True)
    assert (tmp_path / "keep.txt").exists() and not (tmp_path / "times.txt").exists()
    msg = ""
    try:
        prepare_out_dir(tmp_path, force=False)
    except ConfigError as err:
        msg = str(err)
    assert "\n" not in msg and "not empty" in msg


# ------------------------------------------------------------------------------ end to end


@pytest.fixture(scope="module")
def two_runs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    from amrvio.sim.simulate import SimConfig, simulate

    cfg = SimConfig(scene="corridor", motion="forward-stop-turn", seed=3, ev_steps="1.0:+1",
                    blur_bursts="0.5:0.4:3.0", width=160, height=120, seconds=2.0, fps=10.0)
    a = tmp_path_factory.mktemp("sim_a")
    b = tmp_path_factory.mktemp("sim_b")
    summary = simulate(cfg, a)
    simulate(cfg, b)
    # the blur burst (peak 3 rad/s, 12 ms, f = 97.6 px) smears the centre by up to f w T = 3.5 px,
    # the image corners by up to (1 + (x/f)^2) times more (x = 80 px: 1.67)
    assert 2.0 < summary.max_smear_px < 3.6 * 1.7
    return a, b


def test_same_seed_gives_byte_identical_trees(two_runs: tuple[Path, Path]) -> None:
    a, b = two_runs
    ta, tb = _tree(a), _tree(b)
    assert len(ta) == 20 + 11  # 20 PNG frames + 11 other files
    assert ta.keys() == tb.keys()
    for name in ta:
        assert ta[name] == tb[name], name


def test_output_reads_back_through_open_dataset(two_runs: tuple[Path, Path]) -> None:
    from amrvio.io.dataset import open_dataset
    from amrvio.io.trajectory import read_euroc_csv

    out = two_runs[0]
    ds = open_dataset(f"euroc:{out}")
    assert ds.kind == "euroc" and len(ds.frames) == 20
    assert ds.camera is not None and ds.camera.width == 160 and ds.camera.fx == pytest.approx(97.6)
    stamps = ds.frame_stamps_ns
    np.testing.assert_array_equal(np.diff(stamps), 100_000_000)
    assert stamps[0] == 1_000_000_000 + 50_000_000  # mid-exposure stamp of frame 0
    img = ds.frames[3].load()
    assert img.shape == (120, 160) and img.dtype == np.uint8 and 5 < img.mean() < 250
    assert ds.imu is not None and len(ds.imu) == 401
    assert ds.groundtruth is not None and len(ds.groundtruth) == 401
    assert ds.T_body_cam is not None
    assert ds.inverse_response is not None and ds.inverse_response.shape == (256,)
    assert ds.vignette is not None and ds.vignette.shape == (120, 160)
    gt = read_euroc_csv(out / "mav0/state_groundtruth_estimate0/data.csv")
    assert gt.velocities_m_s is not None and gt.gyro_bias is not None and gt.accel_bias is not None
    # the written IMU equals the true specific force + true bias + white noise of the EuRoC size
    from amrvio.sim.imu_synth import ideal_imu
    from amrvio.sim.motion import parse_blur_bursts
    from amrvio.sim.scene import make_scene
    from amrvio.sim.simulate import layout_for_scene

    m = make_motion("forward-stop-turn", 2.0, layout_for_scene(make_scene("corridor", 3)), 3,
                    parse_blur_bursts("0.5:0.4:3.0"))
    t = (ds.imu.stamps_ns - 1_000_000_000) * 1e-9
    g_true, a_true = ideal_imu(m.states(t))
    white = ds.imu.gyro_rad_s - g_true - gt.gyro_bias
    assert 0.5 * 1.6968e-4 * math.sqrt(200) < white.std() < 2 * 1.6968e-4 * math.sqrt(200)
    np.testing.assert_allclose(gt.trajectory.positions_m, m.states(t).p_world, atol=1e-12)
    # times.txt: exposures whole microseconds, +1 EV at t = 1 s
    rows = [line.split() for line in (out / "times.txt").read_text().splitlines()]
    assert len(rows) == 20
    exp_ms = np.array([float(r[2]) for r in rows])
    t_s = np.array([float(r[1]) for r in rows])
    np.testing.assert_allclose(t_s, stamps * 1e-9)
    np.testing.assert_allclose(exp_ms, np.where(t_s - 1.0 >= 1.0, 24.0, 12.0))
    assert (out / "wheel_odometry.csv").read_text().count("\n") == 101 + 1
    assert (out / "sim_config.yaml").read_text().count("seed: 3") == 1
    # sim_frames.csv: one row per frame, aligned with the frame stamps and times.txt
    from amrvio.sim.writer import read_frames_csv

    truth = read_frames_csv(out / "sim_frames.csv")
    np.testing.assert_array_equal([r.t_ns for r in truth], stamps)
    np.testing.assert_allclose([r.exposure_s * 1e3 for r in truth], exp_ms)
    np.testing.assert_allclose([r.mean_intensity_dn for r in truth],
                               [f.load().mean() for f in ds.frames])
    smear = np.array([r.smear_px_max for r in truth])
    assert smear.max() > 2.0 and np.all(np.array([r.smear_px_center for r in truth]) <= smear)
    assert all(r.n_subframes % 2 == 1 and r.n_subframes >= r.smear_px_max / 0.5 for r in truth)


def test_noise_free_run_integrates_back_to_groundtruth(tmp_path: Path) -> None:
    """Read the written IMU and GT files, integrate (RK4), compare: the file chain is exact."""
    from amrvio.io.dataset import open_dataset
    from amrvio.io.trajectory import read_euroc_csv
    from amrvio.sim.simulate import SimConfig, simulate
    from amrvio.types.lie import quat_wxyz_to_matrix
    from tests.sim.test_imu_synth import _rk4_integrate

    cfg = SimConfig(scene="room", motion="handheld", imu_noise=False, blur=False, width=64,
                    height=48, seconds=3.0, fps=5.0)
    simulate(cfg, tmp_path)
    # sensor.yaml keeps nominal densities for the estimator and says the data are exact
    assert "EXACT data" in (tmp_path / "mav0/imu0/sensor.yaml").read_text()
    ds = open_dataset(f"euroc:{tmp_path}")
    gt = read_euroc_csv(tmp_path / "mav0/state_groundtruth_estimate0/data.csv")
    assert ds.imu is not None and gt.velocities_m_s is not None
    np.testing.assert_array_equal(gt.stamps_ns, ds.imu.stamps_ns)
    R0 = quat_wxyz_to_matrix(gt.trajectory.quats_wxyz[:1])[0]
    pos = _rk4_integrate(R0, gt.velocities_m_s[0], gt.trajectory.positions_m[0],
                         ds.imu.gyro_rad_s, ds.imu.accel_m_s2, 1 / 200)
    err = np.linalg.norm(pos - gt.trajectory.positions_m[::2][: len(pos)], axis=1)
    assert err.max() < 1e-3


@pytest.mark.parametrize("camera_model", ["pinhole", "radtan"])
def test_frames_are_rendered_at_the_written_groundtruth_pose(tmp_path: Path,
                                                             camera_model: str) -> None:
    """Re-render a frame from the files alone (GT pose at the frame stamp, T_BS, intrinsics,
    exposure from times.txt): it equals the written image. This checks the whole pose chain."""
    from amrvio.io.dataset import open_dataset
    from amrvio.io.trajectory import read_euroc_csv
    from amrvio.sim.image_formation import SensorModel, render_frame
    from amrvio.sim.render import SceneRenderer
    from amrvio.sim.scene import make_scene
    from amrvio.sim.simulate import SimConfig, simulate
    from amrvio.types.lie import SE3

    cfg = SimConfig(scene="room", motion="forward-stop-turn", seconds=4.0, fps=2.0, width=96,
                    height=64, blur=False, sensor_noise=False, camera_model=camera_model, seed=1)
    simulate(cfg, tmp_path)
    ds = open_dataset(f"euroc:{tmp_path}")
    gt = read_euroc_csv(tmp_path / "mav0/state_groundtruth_estimate0/data.csv")
    assert ds.camera is not None and ds.T_body_cam is not None
    assert ds.camera.distortion_model == ("radtan" if camera_model == "radtan" else "none")
    renderer = SceneRenderer(make_scene("room", 1), ds.camera)
    exposures_ms = [float(r.split()[2]) for r in (tmp_path / "times.txt").read_text().splitlines()]
    for k in (1, 6):
        frame = ds.frames[k]
        i = int(np.searchsorted(gt.stamps_ns, frame.t_ns))
        assert gt.stamps_ns[i] == frame.t_ns
        T_wb = SE3.from_quat_wxyz(gt.trajectory.quats_wxyz[i], gt.trajectory.positions_m[i])
        T_wc = T_wb @ ds.T_body_cam
        e = exposures_ms[k] * 1e-3

        def pose_at(t: float, T: SE3 = T_wc) -> SE3:
            return T

        again = render_frame(renderer, pose_at, frame.t_s - e / 2, e, SensorModel(noise=False),
                             None, blur=False)
        diff = np.abs(again.image.astype(int) - frame.load().astype(int))
        assert diff.max() <= 1 and diff.mean() < 0.01


def test_cli_simulate_writes_and_refuses_to_overwrite(tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    from amrvio.cli.main import main

    out = tmp_path / "seq"
    argv = ["simulate", "--scene", "warehouse", "--motion", "rough-floor", "--seconds", "1",
            "--fps", "4", "--resolution", "48x32", "--imu-noise", "off", "--blur", "off",
            "--auto-exposure", "--out", str(out)]
    assert main(argv) == 0
    assert "4 frames" in capsys.readouterr().out
    assert main(argv) == 1
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "--force" in err
    assert main([*argv, "--force"]) == 0
    assert len(list((out / "mav0/cam0/data").iterdir())) == 4
    assert main(["simulate", "--motion", "replay", "--out", str(tmp_path / "x")]) == 1
    assert "--trajectory" in capsys.readouterr().err
    for bad in (["--seed", "-3"], ["--seconds", "0"], ["--imu-rate", "nan"],
                ["--ev-steps", "1:x"], ["--motion", "replay", "--trajectory", str(tmp_path / "no.csv")]):
        assert main(["simulate", *bad, "--out", str(tmp_path / "y")]) == 1, bad
        err = capsys.readouterr().err.strip()
        assert err and "\n" not in err and "Traceback" not in err, bad


@pytest.mark.parametrize("scene_name", ["corridor", "warehouse", "room", "wall"])
def test_every_motion_stays_in_the_free_floor_area(scene_name: str) -> None:
    from amrvio.sim.motion import MOTION_KINDS
    from amrvio.sim.scene import make_scene
    from amrvio.sim.simulate import layout_for_scene

    scene = make_scene(scene_name, 0)
    for kind in MOTION_KINDS:
        for seconds in (10.0, 60.0):
            m = make_motion(kind, seconds, layout_for_scene(scene), seed=1,
                            blur_bursts=parse_blur_bursts("1:1:3"))
            p = m.states(np.linspace(0.0, seconds, 2001)).p_world
            assert np.all(p[:, :2] >= scene.free_xy_min - 1e-9), (kind, seconds)
            assert np.all(p[:, :2] <= scene.free_xy_max + 1e-9), (kind, seconds)
            assert np.all(p[:, 2] > 0.2) and np.all(p[:, 2] < scene.bounds_max[2] - 0.5)


def test_auto_exposure_and_photometric_files(tmp_path: Path) -> None:
    from amrvio.io.dataset import open_dataset
    from amrvio.photometric.model import RadialVignette
    from amrvio.sim.image_formation import CameraResponse
    from amrvio.sim.simulate import SimConfig, simulate

    cfg = SimConfig(scene="room", motion="constant-velocity", seconds=2.0, fps=10.0, width=48,
                    height=32, blur=False, exposure_ms=0.1, auto_exposure=True,
                    response_gamma=2.2, vignette_v1=-0.4)
    simulate(cfg, tmp_path)
    ds = open_dataset(f"euroc:{tmp_path}")
    exp_ms = np.array([float(r.split()[2]) for r in (tmp_path / "times.txt").read_text().splitlines()])
    means = np.array([f.load().mean() for f in ds.frames])
    # under-exposed start: the controller raises the exposure at most 0.25 EV per frame
    assert exp_ms[0] == 0.1
    d_ev = np.diff(np.log2(exp_ms))
    np.testing.assert_allclose(d_ev[:3], 0.25, atol=0.01)  # rate limit (whole-microsecond rounding)
    assert np.abs(d_ev).max() < 0.25 + 0.01
    assert abs(means[-1] - 110.0) < abs(means[0] - 110.0) - 20.0  # moves towards the 110 DN target
    assert ds.inverse_response is not None and ds.vignette is not None
    lut = 255.0 * CameraResponse(2.2).inverse(np.arange(256) / 255.0)
    np.testing.assert_allclose(ds.inverse_response, lut, rtol=1e-12, atol=1e-12)
    vmap = RadialVignette(-0.4).map(32, 48)
    np.testing.assert_allclose(ds.vignette, vmap / vmap.max(), atol=2e-5)  # 16-bit, max = 1


def test_analog_gain_equals_longer_exposure(tmp_path: Path) -> None:
    """Energy = gain * t * V * B (image_formation module doc): gain 2 at 5 ms gives the same
    noise-free, blur-free frames as gain 1 at 10 ms; a bad gain is a one-line ConfigError."""
    from amrvio.sim.simulate import SimConfig, simulate

    base = dict(scene="room", motion="handheld", seconds=1.0, fps=4.0, width=48, height=32,
                blur=False, sensor_noise=False, response_gamma=2.2)
    simulate(SimConfig(**base, analog_gain=2.0, exposure_ms=5.0), tmp_path / "g2")  # type: ignore[arg-type]
    simulate(SimConfig(**base, analog_gain=1.0, exposure_ms=10.0), tmp_path / "g1")  # type: ignore[arg-type]
    a = sorted((tmp_path / "g2/mav0/cam0/data").iterdir())
    b = sorted((tmp_path / "g1/mav0/cam0/data").iterdir())
    assert len(a) == len(b) == 4
    for pa, pb in zip(a, b, strict=True):
        assert pa.name == pb.name and pa.read_bytes() == pb.read_bytes()
    assert "analog_gain: 2.0" in (tmp_path / "g2/sim_config.yaml").read_text()
    for bad in (0.0, float("nan"), 100.0):
        with pytest.raises(ConfigError, match="analog gain"):
            SimConfig(analog_gain=bad)
