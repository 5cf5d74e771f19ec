"""Trajectory files: TUM, KITTI, EuRoC CSV round trips, detection and bad input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from amrvio.errors import TrajectoryFormatError
from amrvio.io.trajectory import (
    EurocGroundTruth,
    detect_format,
    read_euroc_csv,
    read_kitti,
    read_trajectory,
    read_tum,
    write_euroc_csv,
    write_kitti,
    write_trajectory,
    write_tum,
)
from amrvio.types.lie import matrix_to_quat_wxyz, so3_exp
from amrvio.types.trajectory import Trajectory


def _traj(n: int = 30, seed: int = 3, t0: float = 1403715273.262143) -> Trajectory:
    rng = np.random.default_rng(seed)
    stamps = t0 + np.cumsum(rng.uniform(0.03, 0.07, n))
    pos = np.cumsum(rng.normal(0, 0.3, (n, 3)), axis=0)
    R = so3_exp(rng.normal(0, 1.0, (n, 3)))
    return Trajectory(stamps, pos, matrix_to_quat_wxyz(R))


def _same_rotations(a: Trajectory, b: Trajectory, tol: float = 1e-15) -> None:
    np.testing.assert_allclose(a.rotations(), b.rotations(), rtol=0, atol=tol)


def test_tum_round_trip_exact(tmp_path: Path) -> None:
    t = _traj()
    p = tmp_path / "a.txt"
    write_tum(p, t)
    r = read_tum(p)
    np.testing.assert_array_equal(r.stamps_s, t.stamps_s)
    np.testing.assert_array_equal(r.positions_m, t.positions_m)
    # Trajectory re-normalises the quaternion: equal up to rounding of that division.
    np.testing.assert_allclose(r.quats_wxyz, t.quats_wxyz, rtol=0, atol=2e-16)
    assert detect_format(p) == "tum"


def test_tum_reads_comments_blank_lines_and_tabs(tmp_path: Path) -> None:
    p = tmp_path / "c.txt"
    p.write_text("# header\n\n1.0 1 2 3 0 0 0 1\n  # indented comment\n2.0\t4 5 6 0 0 1 0\n")
    t = read_tum(p)
    assert len(t) == 2
    np.testing.assert_array_equal(t.positions_m, [[1, 2, 3], [4, 5, 6]])
    np.testing.assert_array_equal(t.quats_wxyz, [[1, 0, 0, 0], [0, 0, 0, 1]])


def test_tum_normalises_nearly_unit_quaternion(tmp_path: Path) -> None:
    p = tmp_path / "q.txt"
    p.write_text("0 0 0 0 0 0 0 1.0005\n")
    q = read_tum(p).quats_wxyz[0]
    np.testing.assert_allclose(q, [1, 0, 0, 0], atol=1e-15)


def test_kitti_round_trip_with_times(tmp_path: Path) -> None:
    t = _traj(seed=4)
    p, tp = tmp_path / "poses.txt", tmp_path / "times.txt"
    write_kitti(p, t, tp)
    r = read_kitti(p, tp)
    np.testing.assert_array_equal(r.stamps_s, t.stamps_s)
    np.testing.assert_array_equal(r.positions_m, t.positions_m)
    _same_rotations(r, t, 1e-15)
    assert detect_format(p) == "kitti"
    r2 = read_trajectory(p, times=tp)
    np.testing.assert_array_equal(r2.positions_m, t.positions_m)


def test_kitti_without_times_uses_index_and_projects_rounded_rotations(tmp_path: Path) -> None:
    p = tmp_path / "poses.txt"
    # Rotation blocks rounded to 7 digits like the KITTI files (|R R^T - I| ~ 1e-7).
    p.write_text(
        "1.000000e+00 0 0 1.5 0 1.000000e+00 0 2.5 0 0 9.999999e-01 3.5\n"
        "0 -1 0 0 1 0 0 0 0 0 1 7\n"
    )
    t = read_kitti(p)
    np.testing.assert_array_equal(t.stamps_s, [0.0, 1.0])
    np.testing.assert_array_equal(t.positions_m, [[1.5, 2.5, 3.5], [0, 0, 7]])
    R = t.rotations()
    np.testing.assert_allclose(R @ np.transpose(R, (0, 2, 1)), np.broadcast_to(np.eye(3), R.shape),
                               atol=1e-14)
    np.testing.assert_allclose(R[1], [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-15)


def test_euroc_round_trip_full_columns(tmp_path: Path) -> None:
    t = _traj(seed=5)
    rng = np.random.default_rng(0)
    ns = (np.round(t.stamps_s * 1e9)).astype(np.int64)
    gt = EurocGroundTruth(t, ns, rng.normal(size=(len(t), 3)), rng.normal(size=(len(t), 3)),
                          rng.normal(size=(len(t), 3)))
    p = tmp_path / "data.csv"
    write_euroc_csv(p, gt)
    r = read_euroc_csv(p)
    np.testing.assert_array_equal(r.stamps_ns, ns)
    assert r.stamps_ns.dtype == np.int64
    np.testing.assert_array_equal(r.trajectory.positions_m, t.positions_m)
    np.testing.assert_allclose(r.trajectory.quats_wxyz, t.quats_wxyz, rtol=0, atol=2e-16)
    assert r.velocities_m_s is not None and r.gyro_bias is not None and r.accel_bias is not None
    np.testing.assert_array_equal(r.velocities_m_s, gt.velocities_m_s)
    np.testing.assert_array_equal(r.gyro_bias, gt.gyro_bias)
    np.testing.assert_array_equal(r.accel_bias, gt.accel_bias)
    np.testing.assert_allclose(r.trajectory.stamps_s, ns * 1e-9, rtol=1e-15)
    assert detect_format(p) == "euroc"


def test_euroc_plain_8_columns(tmp_path: Path) -> None:
    p = tmp_path / "plain.txt"  # no .csv: detected by the commas
    p.write_text("t_ns,px,py,pz,qw,qx,qy,qz\n".replace("t_ns", "#t_ns")
                 + "1403715273262142976,1,2,3,1,0,0,0\n1403715273312143104,4,5,6,0,1,0,0\n")
    assert detect_format(p) == "euroc"
    r = read_euroc_csv(p)
    assert r.velocities_m_s is None and r.gyro_bias is None and r.accel_bias is None
    np.testing.assert_array_equal(r.stamps_ns, [1403715273262142976, 1403715273312143104])
    tr = read_trajectory(p)
    np.testing.assert_array_equal(tr.positions_m, [[1, 2, 3], [4, 5, 6]])
    # Writing a bare Trajectory gives 8 columns that read back the same.
    q = tmp_path / "w.csv"
    write_trajectory(q, tr)
    assert len(q.read_text().splitlines()[1].split(",")) == 8
    np.testing.assert_array_equal(read_euroc_csv(q).stamps_ns, r.stamps_ns)


def test_write_trajectory_auto_formats(tmp_path: Path) -> None:
    t = _traj(n=5, seed=6, t0=0.0)
    for name, fmt in (("a.tum", "tum"), ("b.kitti", "kitti"), ("c.csv", "euroc")):
        write_trajectory(tmp_path / name, t)
        assert detect_format(tmp_path / name) == fmt
        r = read_trajectory(tmp_path / name)
        np.testing.assert_allclose(r.positions_m, t.positions_m, rtol=0, atol=0)


# ----------------------------------------------------------------------------------- bad input

_TUM_OK = "1.0 0 0 0 0 0 0 1\n"


@pytest.mark.parametrize(
    ("body", "line", "needle"),
    [
        (_TUM_OK + "2.0 0 0 zero 0 0 0 1\n", 2, "cannot read 'zero'"),
        (_TUM_OK + "2.0 0 0 0 0 0 1\n", 2, "expected 8 columns"),
        ("# c\n" + _TUM_OK + "2.0 0 nan 0 0 0 0 1\n", 3, "not finite"),
        (_TUM_OK + "2.0 0 0 0 0 0 0 inf\n", 2, "not finite"),
        (_TUM_OK + "2.0 0 0 0 0 0 0 0.9\n", 2, "quaternion norm"),
        (_TUM_OK + "3.0 0 0 0 0 0 0 1\n2.5 0 0 0 0 0 0 1\n", 3, "goes backwards"),
        (_TUM_OK + "1.0 0 0 0 0 0 0 1\n", 2, "repeats"),
    ],
)
def test_tum_bad_input_names_file_and_line(
    tmp_path: Path, body: str, line: int, needle: str
) -> None:
    p = tmp_path / "bad_traj.txt"
    p.write_text(body)
    with pytest.raises(TrajectoryFormatError) as info:
        read_tum(p)
    msg = str(info.value)
    assert msg.startswith(f"{p}:{line}: "), msg
    assert needle in msg
    assert "\n" not in msg
    assert info.value.line == line


def test_empty_and_missing_files(tmp_path: Path) -> None:
    p = tmp_path / "empty.txt"
    p.write_text("# only a comment\n")
    with pytest.raises(TrajectoryFormatError, match="no poses"):
        read_tum(p)
    with pytest.raises(TrajectoryFormatError, match="file not found"):
        read_trajectory(tmp_path / "missing.txt")
    with pytest.raises(TrajectoryFormatError, match="no poses"):
        read_trajectory(p)


def test_detect_format_unknown_column_count(tmp_path: Path) -> None:
    p = tmp_path / "odd.txt"
    p.write_text("# x\n1 2 3 4 5\n")
    with pytest.raises(TrajectoryFormatError) as info:
        read_trajectory(p)
    assert str(info.value).startswith(f"{p}:2: ")
    assert "5 columns" in str(info.value)


def test_kitti_bad_input(tmp_path: Path) -> None:
    good = "1 0 0 0 0 1 0 0 0 0 1 0\n"
    p = tmp_path / "poses.txt"
    p.write_text(good + "1 0 0 0 0 1 0 0 0 0 1\n")
    with pytest.raises(TrajectoryFormatError, match=r"poses.txt:2: expected 12 columns"):
        read_kitti(p)
    p.write_text(good + "2 0 0 0 0 1 0 0 0 0 1 0\n")
    with pytest.raises(TrajectoryFormatError, match=r"poses.txt:2: the 3x3 block is not a rotation"):
        read_kitti(p)
    p.write_text(good + "-1 0 0 0 0 1 0 0 0 0 1 0\n")  # a reflection, det = -1
    with pytest.raises(TrajectoryFormatError, match=r"poses.txt:2: .*det = -1"):
        read_kitti(p)
    p.write_text(good + "1 0 0 0 0 1 0 0 0 0 1 NaN\n")
    with pytest.raises(TrajectoryFormatError, match=r"poses.txt:2: column 12: .*not finite"):
        read_kitti(p)
    p.write_text(good + good)
    tp = tmp_path / "times.txt"
    tp.write_text("0.0\n0.1\n0.2\n")
    with pytest.raises(TrajectoryFormatError, match=r"times.txt: has 3 stamps but .* 2 poses"):
        read_kitti(p, tp)
    tp.write_text("0.0\n# c\n0.0\n")
    with pytest.raises(TrajectoryFormatError, match=r"times.txt:3: timestamp 0.0 repeats"):
        read_kitti(p, tp)
    tp.write_text("0.0\nabc\n")
    with pytest.raises(TrajectoryFormatError, match=r"times.txt:2: column 1: cannot read 'abc'"):
        read_kitti(p, tp)


def test_euroc_bad_input(tmp_path: Path) -> None:
    head = "#t,px,py,pz,qw,qx,qy,qz\n"
    ok = "1000,0,0,0,1,0,0,0\n"
    p = tmp_path / "data.csv"
    cases = [
        (head + ok + "2000,0,0,0,1,0,0\n", 3, "expected 8 or 11 or 14 or 17 columns"),
        (head + ok + "2000,0,0,0,1,0,0,0,1,2,3\n", 3, "11 columns where earlier lines have 8"),
        (head + ok + "2000.5,0,0,0,1,0,0,0\n", 3, "not an integer number of nanoseconds"),
        (head + ok + "900,0,0,0,1,0,0,0\n", 3, "goes backwards"),
        (head + ok + "2000,0,x,0,1,0,0,0\n", 3, "column 3: cannot read 'x'"),
        (head + ok + "2000,0,0,0,nan,0,0,0\n", 3, "column 5: value 'nan' is not finite"),
        (head + ok + "2000,0,0,0,2,0,0,0\n", 3, "quaternion norm 2"),
    ]
    for body, line, needle in cases:
        p.write_text(body)
        with pytest.raises(TrajectoryFormatError) as info:
            read_euroc_csv(p)
        msg = str(info.value)
        assert msg.startswith(f"{p}:{line}: "), msg
        assert needle in msg, msg


def test_times_only_for_kitti(tmp_path: Path) -> None:
    p = tmp_path / "a.tum"
    p.write_text(_TUM_OK)
    with pytest.raises(TrajectoryFormatError, match="only applies to KITTI"):
        read_trajectory(p, times=tmp_path / "t.txt")
    with pytest.raises(TrajectoryFormatError, match="unknown trajectory format"):
        read_trajectory(p, fmt="g2o")
