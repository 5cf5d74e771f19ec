"""Wheel-odometry reader (amrvio.io.wheel): the distance integral against a closed form, the
simulator's file read back, and bad lines named."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from amrvio.errors import DatasetFormatError
from amrvio.io.wheel import read_wheel_csv


def _write(path: Path, t_ns: np.ndarray, v: np.ndarray) -> Path:
    rows = ["timestamp_ns,v_forward_m_s,yaw_rate_rad_s,v_forward_true_m_s,yaw_rate_true_rad_s,slipping"]
    rows += [f"{int(t)},{x:.9f},0.1,{x:.9f},0.1,0" for t, x in zip(t_ns, v, strict=True)]
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    return path


def test_distance_integrates_the_speed(tmp_path: Path) -> None:
    t = np.arange(0, 4_000_000_001, 20_000_000, dtype=np.int64)
    v = 0.5 * t * 1e-9  # constant acceleration 0.5 m/s^2: distance 0.25 t^2
    w = read_wheel_csv(_write(tmp_path / "w.csv", t, v))
    assert len(w) == t.shape[0]
    assert w.distance_m(1_000_000_000, 3_000_000_000) == pytest.approx(0.25 * (9 - 1), rel=1e-9)
    assert w.distance_m(1_010_000_000, 2_990_000_000) == pytest.approx(0.25 * (2.99**2 - 1.01**2), rel=1e-6)
    assert w.speed_at(2_000_000_000) == pytest.approx(1.0)
    assert np.isnan(w.distance_m(-1, 10)) and np.isnan(w.speed_at(5_000_000_000))


def test_bad_lines_are_named(tmp_path: Path) -> None:
    p = tmp_path / "bad.csv"
    p.write_text("timestamp_ns,v,w\n100,0.1,0.0\n50,0.1,0.0\n", encoding="utf-8")
    with pytest.raises(DatasetFormatError, match="increase") as err:
        read_wheel_csv(p)
    assert err.value.line == 3
    p.write_text("timestamp_ns,v,w\n100,abc,0.0\n", encoding="utf-8")
    with pytest.raises(DatasetFormatError, match="expected"):
        read_wheel_csv(p)


def test_the_simulators_file_is_read_with_the_recording(tmp_path: Path) -> None:
    from amrvio.io.dataset import open_dataset
    from amrvio.sim.simulate import SimConfig, simulate

    simulate(SimConfig(motion="constant-velocity", seconds=1.0, width=64, height=48, fps=5.0), tmp_path / "s")
    ds = open_dataset(str(tmp_path / "s"))
    assert ds.wheel is not None and len(ds.wheel) > 10
    # 1 m/s corridor drive, the simulated wheels read 2 % long (plus noise)
    assert ds.wheel.distance_m(int(ds.wheel.stamps_ns[0]), int(ds.wheel.stamps_ns[-1])) == pytest.approx(1.02, abs=0.03)
