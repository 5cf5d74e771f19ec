"""Wheel odometry as the metric scale source: the wheel distance integral (closed forms), the
reader's one-line errors, and ``amrvio run`` on the simulator's corridor at constant velocity,
where no IMU can give the scale, against ground truth."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace
from typing import cast

import numpy as np
import pytest

import amrvio
from amrvio.errors import DatasetFormatError, ShapeError
from amrvio.estimator.local_mapping import Segment
from amrvio.estimator.wheel_scale import WheelScale, WheelScaleConfig
from amrvio.io.base import read_wheel_csv
from amrvio.io.dataset import open_dataset
from amrvio.sim.simulate import SimConfig, simulate
from amrvio.types.sensors import WheelData


def test_distance_is_the_integral_of_the_speed() -> None:
    t = np.arange(0, 11) * 100_000_000  # 0 .. 1 s at 10 Hz
    const = WheelData(t, np.full(11, 0.5), np.zeros(11))
    assert const.distance_m(0, 1_000_000_000) == pytest.approx(0.5, rel=1e-12)
    assert const.distance_m(250_000_000, 650_000_000) == pytest.approx(0.2, rel=1e-12)
    ramp = WheelData(t, np.asarray(t * 2e-9, np.float64), np.zeros(11))  # v = 2 t: distance t1^2 - t0^2
    assert ramp.distance_m(200_000_000, 900_000_000) == pytest.approx(0.81 - 0.04, rel=1e-12)
    reverse = WheelData(t, np.asarray(-t * 2e-9, np.float64), np.zeros(11))  # driving backwards: path length
    assert reverse.distance_m(0, 1_000_000_000) == pytest.approx(1.0, rel=1e-12)
    assert np.isnan(const.distance_m(0, 1_100_000_000))  # not covered
    with pytest.raises(ShapeError):
        WheelData(t[::-1].copy(), np.zeros(11), np.zeros(11))


def test_reader_names_the_file_and_line(tmp_path: Path) -> None:
    good = tmp_path / "wheel_odometry.csv"
    good.write_text("timestamp_ns,v_forward_m_s,yaw_rate_rad_s\n0,0.5,0.0\n100,0.6,0.1\n")
    w = read_wheel_csv(good)
    assert len(w) == 2 and w.v_forward_m_s[1] == 0.6 and w.yaw_rate_rad_s[1] == 0.1
    bad = tmp_path / "bad.csv"
    bad.write_text("timestamp_ns,v_forward_m_s,yaw_rate_rad_s\n0,0.5,0.0\n100,fast,0.1\n")
    with pytest.raises(DatasetFormatError) as err:
        read_wheel_csv(bad)
    msg = str(err.value)
    assert "bad.csv" in msg and "3" in msg and "\n" not in msg
    back = tmp_path / "back.csv"
    back.write_text("0,0.5,0.0\n100,0.6,0.1\n50,0.6,0.1\n")
    with pytest.raises(DatasetFormatError, match="back.csv"):
        read_wheel_csv(back)


def _corridor(root: Path, wheel_error: float) -> Path:
    seq = root / f"cv_{wheel_error:g}"
    simulate(SimConfig(scene="corridor", motion="constant-velocity", seconds=6.0, fps=10.0,
                       width=376, height=240, wheel_scale_error=wheel_error), seq)
    return seq


WHEELS: dict[str, object] = {"scale": {"wheel": {"enabled": True}}}


def _path_scale(seq: Path, config: dict[str, object] | None = None) -> tuple[float, object]:
    """Estimated / true camera path length (a straight path has no Sim3 alignment), and the
    evaluation's metric scale source."""
    res = amrvio.run(seq, config, report=False)
    ds = open_dataset(seq)
    assert ds.wheel is not None and ds.groundtruth is not None and ds.T_body_cam is not None
    out = res.output
    posed = [i for i, r in enumerate(out.records) if r.pose_refined is not None]
    assert len(posed) == len(out.records)
    est = out.T_world_cam[posed, :3, 3]
    gt = ds.groundtruth.right_multiplied(ds.T_body_cam).interpolated_at(
        out.stamps_ns[posed] * 1e-9).positions_m
    length = lambda p: float(np.sum(np.linalg.norm(np.diff(p, axis=0), axis=1)))  # noqa: E731
    source = res.evaluation.summary["metric_scale_source"] if res.evaluation else None
    return length(est) / length(gt), source


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _corridor(tmp_path_factory.mktemp("wheel"), 0.0)


def test_wheels_make_constant_velocity_metric(calibrated: Path, tmp_path: Path) -> None:
    scale, source = _path_scale(calibrated, WHEELS)
    assert source == "wheel_odometry"
    assert abs(scale - 1.0) < 0.01
    # a wheel radius 3 % too large reads 3 % more distance, and the map follows the wheels
    scale_off, _ = _path_scale(_corridor(tmp_path, 0.03), WHEELS)
    assert scale_off == pytest.approx(1.03, abs=0.01)


def test_wheels_only_when_asked(calibrated: Path) -> None:
    # a wheel file alone does not make the camera a ground robot's (hand-held recordings)
    res = amrvio.run(calibrated, report=False, max_frames=20)
    assert res.evaluation is not None
    assert res.evaluation.summary["metric_scale_source"] is None


def test_a_stop_between_two_keyframes_adds_no_distance() -> None:
    """Two keyframes 0.2 m apart in the map (scale 1), the robot drives 0.1 m, stands for 4 s
    and drives 0.1 m between them, with the simulator's 1 cm/s of white speed noise, at 100 Hz.
    The reading is the signed integral, as the map's straight-line distance: 1.0, with a noise
    of 0.01 m/s x sqrt(600) x 0.01 s = 2.4 mm (1.2 %). The integral of |speed| adds
    4 s x 0.8 cm/s = 3.2 cm (1.16)."""
    t = np.arange(0, 6001, 10, dtype=np.int64) * 1_000_000  # 6 s at 100 Hz
    ts = t * 1e-9
    v = np.where(ts < 1.0, 0.1, np.where(ts < 5.0, 0.0, 0.1))
    v = v + np.random.default_rng(0).normal(0.0, 0.01, len(v))
    wheel = WheelData(t, v, np.zeros_like(v))

    def kf(index: int, x: float) -> SimpleNamespace:
        T = np.eye(4)
        T[0, 3] = -x  # T_cam_world of a camera at (x, 0, 0)
        return SimpleNamespace(frame_index=index, T_cam_world=T)

    segment = SimpleNamespace(mapper=SimpleNamespace(map=SimpleNamespace(keyframes=[kf(0, 0.0), kf(1, 0.2)])),
                              world_from_segment=SimpleNamespace(s=1.0))
    ws = WheelScale(wheel, WheelScaleConfig(enabled=True))
    ws.observe_keyframe(cast(Segment, segment), 0)
    ws.frame_scales(2, np.array([0, int(t[-1])], dtype=np.int64))
    (reading,) = ws.wheel_readings
    assert reading.map_units == pytest.approx(0.2)
    assert reading.scale == pytest.approx(1.0, abs=0.04)
    assert wheel.distance_m(0, int(t[-1])) / 0.2 > 1.1  # what the path length would have read
