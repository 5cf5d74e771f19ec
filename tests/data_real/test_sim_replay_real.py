"""Replay of the real EuRoC V1_01 ground truth with its recorded IMU (amrvio simulate --motion replay)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from amrvio.types.lie import quat_wxyz_to_matrix, so3_log
from tests.skip_policy import skip_shared_missing

pytestmark = pytest.mark.real_data

SEQ = "euroc_V1_01_easy_first95"
START_S, SECONDS = 40.0, 10.0


@pytest.fixture(scope="module")
def euroc(shared_data: Path) -> Path:
    mav = shared_data / SEQ / "mav0"
    if not (mav / "state_groundtruth_estimate0" / "data.csv").is_file():
        skip_shared_missing(mav / "state_groundtruth_estimate0" / "data.csv")
    return mav


@pytest.fixture(scope="module")
def replayed(euroc: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    from amrvio.sim.simulate import SimConfig, simulate

    out = tmp_path_factory.mktemp("replay")
    cfg = SimConfig(scene="room", motion="replay", seconds=SECONDS, replay_start_s=START_S,
                    trajectory=str(euroc / "state_groundtruth_estimate0" / "data.csv"),
                    imu_csv=str(euroc / "imu0" / "data.csv"), width=64, height=40, fps=4.0,
                    blur=False)
    simulate(cfg, out)
    return out


def test_replayed_groundtruth_matches_source_within_1mm(euroc: Path, replayed: Path) -> None:
    from amrvio.io.trajectory import read_euroc_csv

    src = read_euroc_csv(euroc / "state_groundtruth_estimate0" / "data.csv")
    out = read_euroc_csv(replayed / "mav0" / "state_groundtruth_estimate0" / "data.csv")
    assert out.stamps_ns[-1] - out.stamps_ns[0] > (SECONDS - 0.01) * 1e9
    inside = (src.stamps_ns >= out.stamps_ns[0]) & (src.stamps_ns <= out.stamps_ns[-1])
    assert inside.sum() >= 195  # 20 Hz source over 10 s
    t_src = (src.stamps_ns[inside] - out.stamps_ns[0]) * 1e-9
    t_out = (out.stamps_ns - out.stamps_ns[0]) * 1e-9
    p_out = np.stack([np.interp(t_src, t_out, out.trajectory.positions_m[:, k]) for k in range(3)], 1)
    err = np.linalg.norm(p_out - src.trajectory.positions_m[inside], axis=1)
    assert err.max() < 1e-3, f"max {err.max() * 1e3:.3f} mm"
    # at the stamps both files share, position and attitude are the source's (spline knots)
    common, i_src, i_out = np.intersect1d(src.stamps_ns, out.stamps_ns, return_indices=True)
    assert common.size >= 150
    np.testing.assert_allclose(out.trajectory.positions_m[i_out], src.trajectory.positions_m[i_src],
                               atol=1e-9)
    R_s = quat_wxyz_to_matrix(src.trajectory.quats_wxyz[i_src])
    R_o = quat_wxyz_to_matrix(out.trajectory.quats_wxyz[i_out])
    ang = np.linalg.norm(so3_log(np.einsum("nji,njk->nik", R_s, R_o)), axis=1)
    assert ang.max() < 1e-8
    assert src.gyro_bias is not None and out.gyro_bias is not None
    np.testing.assert_allclose(out.gyro_bias[i_out], src.gyro_bias[i_src], atol=1e-12)


def test_recorded_imu_is_copied_and_frames_follow(euroc: Path, replayed: Path) -> None:
    from amrvio.io.base import read_imu_csv
    from amrvio.io.dataset import open_dataset

    src = read_imu_csv(euroc / "imu0" / "data.csv")
    ds = open_dataset(f"euroc:{replayed}")
    assert ds.imu is not None and len(ds.imu) >= 2000
    lo = int(np.searchsorted(src.stamps_ns, ds.imu.stamps_ns[0]))
    sl = slice(lo, lo + len(ds.imu))
    np.testing.assert_array_equal(ds.imu.stamps_ns, src.stamps_ns[sl])
    np.testing.assert_array_equal(ds.imu.gyro_rad_s, src.gyro_rad_s[sl])
    np.testing.assert_array_equal(ds.imu.accel_m_s2, src.accel_m_s2[sl])
    assert len(ds.frames) == 40
    assert ds.T_body_cam is not None  # the source's cam0 T_BS
    np.testing.assert_allclose(ds.T_body_cam.t, [-0.0216401454975, -0.064676986768, 0.00981073058949])


def test_replay_spline_derivatives_agree_with_the_recorded_imu(euroc: Path) -> None:
    """The spline's exact angular rate / specific force match the real ADIS16448 after a 0.1 s
    low-pass (the 20 Hz ground truth cannot hold the MAV's vibration)."""
    from amrvio.io.base import read_imu_csv
    from amrvio.sim.imu_synth import ideal_imu
    from amrvio.sim.replay import load_groundtruth, make_replay_motion

    ns, p, q, bg, ba = load_groundtruth(euroc / "state_groundtruth_estimate0" / "data.csv")
    m = make_replay_motion(ns, p, q, START_S, SECONDS, gyro_bias=bg, accel_bias=ba)
    imu = read_imu_csv(euroc / "imu0" / "data.csv").window(m.t0_ns, m.t0_ns + int(SECONDS * 1e9))
    t = (imu.stamps_ns - m.t0_ns) * 1e-9
    g, a = ideal_imu(m.states(t))
    gb, ab = m.gyro_bias_at(t), m.accel_bias_at(t)
    assert gb is not None and ab is not None
    k = np.ones(20) / 20

    def lp(x: np.ndarray) -> np.ndarray:
        return np.stack([np.convolve(x[:, i], k, "same") for i in range(3)], 1)[20:-20]

    rms_g = np.sqrt(np.mean((lp(imu.gyro_rad_s - gb) - lp(g)) ** 2))
    rms_a = np.sqrt(np.mean((lp(imu.accel_m_s2 - ab) - lp(a)) ** 2))
    assert np.sqrt(np.mean(lp(g) ** 2)) > 0.1  # real rotation in this window
    assert rms_g < 0.02 and rms_a < 0.2, (rms_g, rms_a)


@pytest.mark.parametrize("width,height", [(376, 240), (752, 480)])
def test_the_standing_mav_takes_the_static_start_at_either_resolution(euroc: Path, tmp_path: Path, width: int,
                                                                      height: int) -> None:
    """The MAV stands for the flight's first seconds; the replay's tracks move 1.2 mrad in the
    0.4 s of the static start (0.29 px at 376x240, 0.54 px at 752x480): a gate in pixels (0.5)
    took the start at the first resolution only, the angle gate (2.2 mrad) at both."""
    from amrvio.io.dataset import open_dataset
    from amrvio.pipeline.run import run_pipeline
    from amrvio.sim.simulate import SimConfig, simulate

    simulate(SimConfig(scene="room", motion="replay", seconds=1.0, fps=20.0, width=width, height=height,
                       trajectory=str(euroc / "state_groundtruth_estimate0" / "data.csv"),
                       imu_csv=str(euroc / "imu0" / "data.csv"), cam_extrinsic=str(euroc / "cam0" / "sensor.yaml")),
             tmp_path / "r")
    out = run_pipeline(open_dataset(str(tmp_path / "r")), max_frames=12)
    starts = [(r.index, e) for r in out.records for e in r.events if e.startswith("vio_static_init")]
    assert len(starts) == 1 and starts[0][0] <= 9, starts
    assert out.records[-1].estimator.vio is not None and out.records[-1].estimator.vio.init_kind == "static"
