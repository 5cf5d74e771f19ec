"""Dataset readers on small recordings written here: EuRoC, TUM-VI, TUM monoVO, KITTI, folder."""

from __future__ import annotations

import logging
import zipfile
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest

from amrvio.errors import CalibrationError, DatasetFormatError, InputFileError
from amrvio.io.base import Dataset
from amrvio.io.dataset import detect_kind, open_dataset, parse_spec
from amrvio.io.table import seconds_to_ns
from amrvio.types.lie import SE3, SO3
from amrvio.types.sensors import Frame, ImuSample

W, H = 64, 48
T0 = 1_403_715_273_262_142_976  # EuRoC-like nanosecond stamps (beyond float64 precision)
FRAME_DT = 50_000_000
IMU_DT = 5_000_000


def _image(k: int, dtype: type = np.uint8) -> np.ndarray:
    """A distinct deterministic image per frame index k."""
    rng = np.random.default_rng(k)
    img = rng.integers(0, 256, size=(H, W), dtype=np.int64)
    if dtype == np.uint16:
        return (img * 257).astype(np.uint16)
    return img.astype(np.uint8)


def _write_png(path: Path, img: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    assert cv2.imwrite(str(path), img)


def _imu_values(n: int) -> np.ndarray:
    k = np.arange(n, dtype=np.float64)[:, None]
    return np.hstack([0.01 * k + [0.1, 0.2, 0.3], -0.02 * k + [9.81, 0.5, -0.25]])


EUROC_CAM_YAML = """%YAML:1.0
sensor_type: camera
comment: test camera
T_BS:
  cols: 4
  rows: 4
  data: [0.0, -1.0, 0.0, 0.1,
         1.0, 0.0, 0.0, -0.2,
         0.0, 0.0, 1.0, 0.3,
         0.0, 0.0, 0.0, 1.0]
rate_hz: 20
resolution: [{w}, {h}]
camera_model: pinhole
intrinsics: [50.0, 51.0, 31.5, 23.5]
distortion_model: radial-tangential
distortion_coefficients: [-0.1, 0.01, 0.001, 0.002]
"""

EUROC_IMU_YAML = """%YAML:1.0
sensor_type: imu
comment: test imu
T_BS:
  cols: 4
  rows: 4
  data: [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]
rate_hz: 200
gyroscope_noise_density: 1.6968e-04
gyroscope_random_walk: 1.9393e-05
accelerometer_noise_density: 2.0000e-3
accelerometer_random_walk: 3.0000e-3
"""


def make_euroc(root: Path, n_frames: int = 4, n_imu: int = 50, size: tuple[int, int] = (W, H)
               ) -> Path:
    mav = root / "mav0"
    cam = mav / "cam0"
    rows = ["#timestamp [ns],filename"]
    for k in range(n_frames):
        t = T0 + k * FRAME_DT
        _write_png(cam / "data" / f"{t}.png", _image(k))
        rows.append(f"{t},{t}.png")
    (cam / "data.csv").write_text("\n".join(rows) + "\n")
    (cam / "sensor.yaml").write_text(EUROC_CAM_YAML.format(w=size[0], h=size[1]))
    imu = mav / "imu0"
    imu.mkdir(parents=True)
    vals = _imu_values(n_imu)
    lines = ["#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
             "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]"]
    for i in range(n_imu):
        lines.append(f"{T0 + i * IMU_DT}," + ",".join(repr(float(v)) for v in vals[i]))
    (imu / "data.csv").write_text("\n".join(lines) + "\n")
    (imu / "sensor.yaml").write_text(EUROC_IMU_YAML)
    gt = mav / "state_groundtruth_estimate0"
    gt.mkdir(parents=True)
    gt_lines = ["#timestamp,p_x,p_y,p_z,q_w,q_x,q_y,q_z,v_x,v_y,v_z,bw_x,bw_y,bw_z,ba_x,ba_y,ba_z"]
    for i in range(3):
        gt_lines.append(
            f"{T0 + i * FRAME_DT},{0.1 * i},2.0,3.0,1.0,0.0,0.0,0.0,0.1,0,0,0.01,0.02,0.03,0.1,0.2,0.3"
        )
    (gt / "data.csv").write_text("\n".join(gt_lines) + "\n")
    return root


# ------------------------------------------------------------------------------------------------
# EuRoC


def test_euroc_frames_imu_gt_calibration(tmp_path: Path) -> None:
    root = make_euroc(tmp_path / "seq")
    ds = open_dataset(f"euroc:{root}")
    assert ds.kind == "euroc"
    assert [f.t_ns for f in ds.frames] == [T0 + k * FRAME_DT for k in range(4)]
    assert [f.index for f in ds.frames] == [0, 1, 2, 3]
    np.testing.assert_array_equal(ds.frames[2].load(), _image(2))
    # IMU: exact int64 stamps and values as written.
    assert ds.imu is not None and len(ds.imu) == 50
    assert int(ds.imu.stamps_ns[7]) == T0 + 7 * IMU_DT
    vals = _imu_values(50)
    np.testing.assert_array_equal(ds.imu.gyro_rad_s, vals[:, :3])
    np.testing.assert_array_equal(ds.imu.accel_m_s2, vals[:, 3:])
    assert ds.imu_noise is not None and ds.imu_noise.gyro_noise_density == 1.6968e-04
    # Ground truth T_world_body.
    assert ds.groundtruth is not None and len(ds.groundtruth) == 3
    assert ds.groundtruth_frame == "body"
    np.testing.assert_allclose(ds.groundtruth.positions_m[1], [0.1, 2.0, 3.0])
    # Calibration: camera and T_BS (camera pose in body).
    assert ds.camera is not None and ds.camera.fx == 50.0 and ds.camera.cy == 23.5
    assert ds.camera.distortion[:4] == (-0.1, 0.01, 0.001, 0.002)
    assert ds.T_body_cam is not None
    np.testing.assert_allclose(ds.T_body_cam.t, [0.1, -0.2, 0.3])
    np.testing.assert_allclose(ds.T_body_cam.R, [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12)


def test_stream_is_time_ordered_imu_first_at_equal_time(tmp_path: Path) -> None:
    ds = open_dataset(make_euroc(tmp_path / "seq"))  # bare path: detected
    items = list(ds.stream())
    assert ds.imu is not None
    assert len(items) == len(ds.frames) + len(ds.imu)
    stamps = [it.t_ns for it in items]
    assert stamps == sorted(stamps)
    # Frame k sits at the same time as IMU sample 10k: the IMU sample comes first.
    for k, frame in enumerate(ds.frames):
        pos = next(i for i, it in enumerate(items) if it is frame)
        before = items[pos - 1]
        assert isinstance(before, ImuSample) and before.t_ns == frame.t_ns
        assert sum(isinstance(it, ImuSample) for it in items[:pos]) == 10 * k + 1
    assert isinstance(items[-1], ImuSample)


def test_euroc_exposures_from_times_txt_beside_mav0(tmp_path: Path) -> None:
    root = make_euroc(tmp_path / "seq")
    lines = [f"{k:05d} {(T0 + k * FRAME_DT) // 10**9}.{(T0 + k * FRAME_DT) % 10**9:09d} {6.0 + k}"
             for k in range(3)]  # no row for the last frame
    (root / "times.txt").write_text("\n".join(lines) + "\n")
    ds = open_dataset(root)
    assert ds.kind == "euroc"
    assert [f.exposure_s for f in ds.frames] == [0.006, 0.007, 0.008, None]
    (root / "times.txt").write_text(lines[0] + "\n" + lines[1].replace("7.0", "-7.0") + "\n")
    _expect(DatasetFormatError, root / "times.txt", 2, lambda: open_dataset(root))


def test_euroc_mav0_path_and_detection(tmp_path: Path) -> None:
    root = make_euroc(tmp_path / "seq")
    assert detect_kind(root) == "euroc"
    assert detect_kind(root / "mav0") == "euroc"
    (root / "times.txt").write_text(f"00000 {T0 // 10**9}.{T0 % 10**9:09d} 6.5\n")
    ds = open_dataset(str(root / "mav0"))
    assert len(ds.frames) == 4
    assert ds.frames[0].exposure_s == 0.0065  # times.txt beside mav0/ is found from mav0 too


def test_euroc_missing_images_skipped_with_one_counting_warning(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    root = make_euroc(tmp_path / "seq", n_frames=6)
    data = root / "mav0" / "cam0" / "data"
    for k in (1, 4):
        (data / f"{T0 + k * FRAME_DT}.png").unlink()
    with caplog.at_level(logging.WARNING, logger="amrvio.io.base"):
        ds = open_dataset(f"euroc:{root}")
    assert [f.t_ns for f in ds.frames] == [T0 + k * FRAME_DT for k in (0, 2, 3, 5)]
    assert [f.index for f in ds.frames] == [0, 1, 2, 3]
    warnings = [r for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1
    assert "skipped 2 of 6" in warnings[0].getMessage()


def _expect(
    exc_type: type[InputFileError], path: Path, line: int | None, fn: Callable[[], object]
) -> str:
    with pytest.raises(exc_type) as info:
        fn()
    err = info.value
    assert Path(err.path) == path
    assert err.line == line
    text = str(err)
    assert "\n" not in text
    assert text.startswith(f"{path}:{line}:" if line is not None else f"{path}:")
    return text


def _replace_line(path: Path, number: int, new: str) -> None:
    lines = path.read_text().splitlines()
    lines[number - 1] = new
    path.write_text("\n".join(lines) + "\n")


def test_euroc_bad_camera_csv_lines(tmp_path: Path) -> None:
    root = make_euroc(tmp_path / "seq")
    csv = root / "mav0" / "cam0" / "data.csv"
    original = csv.read_text()
    # Malformed line (not a number).
    _replace_line(csv, 3, f"12x4,{T0 + FRAME_DT}.png")
    msg = _expect(DatasetFormatError, csv, 3, lambda: open_dataset(f"euroc:{root}"))
    assert "not an integer" in msg
    # Missing column.
    csv.write_text(original)
    _replace_line(csv, 4, f"{T0 + 2 * FRAME_DT}")
    msg = _expect(DatasetFormatError, csv, 4, lambda: open_dataset(f"euroc:{root}"))
    assert "columns" in msg
    # Time going backwards.
    csv.write_text(original)
    _replace_line(csv, 4, f"{T0},{T0 + 2 * FRAME_DT}.png")
    msg = _expect(DatasetFormatError, csv, 4, lambda: open_dataset(f"euroc:{root}"))
    assert "repeats" in msg or "backwards" in msg
    _replace_line(csv, 4, f"{T0 - 5},{T0 + 2 * FRAME_DT}.png")
    msg = _expect(DatasetFormatError, csv, 4, lambda: open_dataset(f"euroc:{root}"))
    assert "backwards" in msg


def test_euroc_bad_imu_lines(tmp_path: Path) -> None:
    root = make_euroc(tmp_path / "seq")
    imu = root / "mav0" / "imu0" / "data.csv"
    original = imu.read_text()
    _replace_line(imu, 6, f"{T0 + 4 * IMU_DT},0.1,0.2,nan,9.8,0,0")
    msg = _expect(DatasetFormatError, imu, 6, lambda: open_dataset(f"euroc:{root}"))
    assert "NaN" in msg
    imu.write_text(original)
    _replace_line(imu, 9, f"{T0 + 7 * IMU_DT},0.1,0.2,0.3,9.8,0")
    _expect(DatasetFormatError, imu, 9, lambda: open_dataset(f"euroc:{root}"))
    imu.write_text(original)
    _replace_line(imu, 9, f"{T0 + 7 * IMU_DT},0.1,0.2,abc,9.8,0,0")
    msg = _expect(DatasetFormatError, imu, 9, lambda: open_dataset(f"euroc:{root}"))
    assert "'abc'" in msg
    imu.write_text(original)
    _replace_line(imu, 9, f"{T0 + 2 * IMU_DT},0.1,0.2,0.3,9.8,0,0")
    msg = _expect(DatasetFormatError, imu, 9, lambda: open_dataset(f"euroc:{root}"))
    assert "backwards" in msg


def test_euroc_bad_groundtruth_and_empty_imu(tmp_path: Path) -> None:
    root = make_euroc(tmp_path / "seq")
    gt = root / "mav0" / "state_groundtruth_estimate0" / "data.csv"
    _replace_line(gt, 3, f"{T0 + FRAME_DT},0.1,nan,3.0,1.0,0.0,0.0,0.0,0.1,0,0,0,0,0,0,0,0")
    _expect(DatasetFormatError, gt, 3, lambda: open_dataset(f"euroc:{root}"))
    gt.unlink()
    imu = root / "mav0" / "imu0" / "data.csv"
    imu.write_text("#timestamp [ns],wx,wy,wz,ax,ay,az\n")
    msg = _expect(DatasetFormatError, imu, None, lambda: open_dataset(f"euroc:{root}"))
    assert "no data rows" in msg


def test_euroc_undecodable_image_raises_at_load(tmp_path: Path) -> None:
    root = make_euroc(tmp_path / "seq")
    bad = root / "mav0" / "cam0" / "data" / f"{T0 + 2 * FRAME_DT}.png"
    bad.write_bytes(b"\x89PNG not really an image")
    ds = open_dataset(f"euroc:{root}")  # only the first image is read when opening
    ds.frames[1].load()
    msg = _expect(DatasetFormatError, bad, None, ds.frames[2].load)
    assert "decoded" in msg


def test_euroc_calibration_size_mismatch_names_sensor_yaml(tmp_path: Path) -> None:
    root = make_euroc(tmp_path / "seq", size=(640, 480))
    yaml_path = root / "mav0" / "cam0" / "sensor.yaml"
    msg = _expect(CalibrationError, yaml_path, 12, lambda: open_dataset(f"euroc:{root}"))
    assert "640x480" in msg and f"{W}x{H}" in msg


def test_calib_override_orbslam_settings(tmp_path: Path) -> None:
    root = make_euroc(tmp_path / "seq", size=(640, 480))
    settings = tmp_path / "live.yaml"
    settings.write_text(
        "%YAML:1.0\nFile.version: \"1.0\"\nCamera.type: \"PinHole\"\n"
        "Camera1.fx: 60.0\nCamera1.fy: 61.0\nCamera1.cx: 32.0\nCamera1.cy: 24.0\n"
        "Camera1.k1: -0.02\nCamera1.k2: 0.05\nCamera1.p1: -0.0004\nCamera1.p2: 0.001\n"
        f"Camera.width: {W}\nCamera.height: {H}\n"
        "IMU.T_b_c1: !!opencv-matrix\n   rows: 4\n   cols: 4\n   dt: f\n"
        "   data: [1.0, 0.0, 0.0, 0.5, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]\n"
    )
    ds = open_dataset(f"euroc:{root}", calib=settings)
    assert ds.camera is not None
    assert (ds.camera.width, ds.camera.height, ds.camera.fx, ds.camera.cy) == (W, H, 60.0, 24.0)
    assert ds.camera.distortion[:4] == (-0.02, 0.05, -0.0004, 0.001)
    assert ds.T_body_cam is not None
    np.testing.assert_allclose(ds.T_body_cam.t, [0.5, 0.0, 0.0])
    with pytest.raises(CalibrationError):
        open_dataset(f"euroc:{root}", calib=tmp_path / "absent.yaml")


# ------------------------------------------------------------------------------------------------
# TUM-VI


def make_tumvi(root: Path, n_frames: int = 3) -> tuple[Path, SE3]:
    mav = root / "mav0"
    rows = ["#timestamp [ns],filename"]
    times = ["# frame_id timestamp exposure_ms"]
    for k in range(n_frames):
        t = T0 + k * FRAME_DT
        _write_png(mav / "cam0" / "data" / f"{t}.png", _image(k, np.uint16))
        rows.append(f"{t},{t}.png")
        times.append(f"{t} {t // 10**9}.{t % 10**9:09d} {1.5 + k}")
    (mav / "cam0" / "data.csv").write_text("\n".join(rows) + "\n")
    (mav / "imu0").mkdir(parents=True)
    vals = _imu_values(20)
    (mav / "imu0" / "data.csv").write_text(
        "#timestamp [ns],wx,wy,wz,ax,ay,az\n"
        + "".join(f"{T0 + i * IMU_DT}," + ",".join(map(repr, vals[i].tolist())) + "\n"
                  for i in range(20))
    )
    (mav / "mocap0").mkdir(parents=True)
    (mav / "mocap0" / "data.csv").write_text(
        "#timestamp [ns], p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], "
        "q_RS_y [], q_RS_z []\n"
        f"{T0},1.0,2.0,3.0,1.0,0.0,0.0,0.0\n{T0 + 8_333_333},1.1,2.0,3.0,1.0,0.0,0.0,0.0\n"
    )
    dso = root / "dso"
    (dso / "cam0").mkdir(parents=True)
    (dso / "cam0" / "times.txt").write_text("\n".join(times) + "\n")
    T_cam_imu = SE3(SO3.exp(np.array([0.1, -0.2, 0.3])), np.array([0.04, -0.01, 0.02]))
    M = T_cam_imu.matrix()
    rows_txt = "\n".join("  - [" + ", ".join(repr(float(v)) for v in M[r]) + "]" for r in range(4))
    (dso / "camchain.yaml").write_text(
        "cam0:\n  T_cam_imu:\n" + rows_txt + "\n"
        "  camera_model: pinhole\n  distortion_coeffs: [0.01, -0.002, 0.003, -0.0004]\n"
        "  distortion_model: equidistant\n  intrinsics: [40.0, 40.5, 32.1, 23.9]\n"
        f"  resolution: [{W}, {H}]\n  rostopic: /cam0/image_raw\n"
    )
    (dso / "imu_config.yaml").write_text(
        "accelerometer_noise_density: 0.0028\naccelerometer_random_walk: 0.00086\n"
        "gyroscope_noise_density: 0.00016\ngyroscope_random_walk: 0.000022\n"
        "rostopic: /imu0\nupdate_rate: 200.0\n"
    )
    return root, T_cam_imu


def test_tumvi_layout(tmp_path: Path) -> None:
    root, T_cam_imu = make_tumvi(tmp_path / "dataset-room1_512_16")
    assert detect_kind(root) == "tumvi"
    ds = open_dataset(root)
    assert ds.kind == "tumvi" and len(ds.frames) == 3
    assert [f.exposure_s for f in ds.frames] == pytest.approx([1.5e-3, 2.5e-3, 3.5e-3])
    # 16-bit PNG -> 8-bit: the high byte.
    np.testing.assert_array_equal(ds.frames[1].load(), _image(1))
    assert ds.camera is not None and ds.camera.distortion_model == "equidistant"
    assert ds.camera.fy == 40.5
    assert ds.T_body_cam is not None
    np.testing.assert_allclose(ds.T_body_cam.matrix(), T_cam_imu.inverse().matrix(), atol=1e-12)
    assert ds.imu is not None and len(ds.imu) == 20
    assert ds.imu_noise is not None and ds.imu_noise.accel_noise_density == 0.0028
    assert ds.groundtruth is not None and len(ds.groundtruth) == 2
    np.testing.assert_allclose(ds.groundtruth.positions_m[1], [1.1, 2.0, 3.0])


# ------------------------------------------------------------------------------------------------
# TUM monoVO


def _pcalib_values() -> np.ndarray:
    return np.linspace(0.0, 255.0, 256) ** 1.1


def _frac(k: int) -> int:
    """Ten fractional digits of frame k's time (one digit finer than a nanosecond)."""
    return 749409199 + k * 333333333


def make_tum_mono(root: Path, n_frames: int = 4, zipped: bool = False) -> Path:
    root.mkdir(parents=True)
    names = [f"{k:05d}.png" for k in range(n_frames)]
    if zipped:
        with zipfile.ZipFile(root / "images.zip", "w") as zf:
            for k, name in enumerate(names):
                ok, buf = cv2.imencode(".png", _image(k))
                assert ok
                zf.writestr(name, buf.tobytes())
    else:
        for k, name in enumerate(names):
            _write_png(root / "images" / name, _image(k))
    (root / "times.txt").write_text(
        "".join(f"{k:05d} 1399381433.{_frac(k):010d} {10.5 + k}\n" for k in range(n_frames))
    )
    (root / "camera.txt").write_text(f"Pinhole 50.0 50.0 31.5 23.5 0\n{W} {H}\ncrop\n{W} {H}\n")
    (root / "pcalib.txt").write_text(" ".join(repr(float(v)) for v in _pcalib_values()) + "\n")
    vig = np.full((H, W), 60000, dtype=np.uint16)
    vig[H // 2, W // 2] = 65535
    _write_png(root / "vignette.png", vig)
    return root


@pytest.mark.parametrize("zipped", [False, True])
def test_tum_mono(tmp_path: Path, zipped: bool) -> None:
    root = make_tum_mono(tmp_path / "sequence_01", zipped=zipped)
    assert detect_kind(root) == "tum-mono"
    ds = open_dataset(root)
    assert ds.kind == "tum-mono" and len(ds.frames) == 4
    # Decimal seconds converted exactly to nanoseconds (the 1e-10 s digit rounded).
    assert ds.frames[0].t_ns == 1399381433_074940920
    assert [f.t_ns for f in ds.frames] == [
        1399381433 * 10**9 + (_frac(k) + 5) // 10 for k in range(4)]
    assert [f.exposure_s for f in ds.frames] == pytest.approx([0.0105, 0.0115, 0.0125, 0.0135])
    for k in (0, 3):
        np.testing.assert_array_equal(ds.frames[k].load(), _image(k))
    assert (ds.frames[0].path is None) == zipped
    assert ds.camera is not None and ds.camera.fx == 50.0
    assert ds.inverse_response is not None
    np.testing.assert_allclose(ds.inverse_response, _pcalib_values())
    assert ds.vignette is not None and ds.vignette.shape == (H, W) and ds.vignette.max() == 1.0


def test_tum_mono_bad_inputs(tmp_path: Path) -> None:
    root = make_tum_mono(tmp_path / "seq")
    times = root / "times.txt"
    original = times.read_text()
    _replace_line(times, 2, "00001 13993814x3.5 10.0")
    _expect(DatasetFormatError, times, 2, lambda: open_dataset(f"tum-mono:{root}"))
    times.write_text(original)
    _replace_line(times, 3, "00002 1399381433.0 10.0")
    msg = _expect(DatasetFormatError, times, 3, lambda: open_dataset(f"tum-mono:{root}"))
    assert "backwards" in msg
    times.write_text(original)
    _replace_line(times, 3, "00002 1399381433.5 nan")
    _expect(DatasetFormatError, times, 3, lambda: open_dataset(f"tum-mono:{root}"))
    times.write_text(original)
    _replace_line(times, 2, "00001")
    _expect(DatasetFormatError, times, 2, lambda: open_dataset(f"tum-mono:{root}"))
    times.write_text(original)
    # Vignette of the wrong size.
    _write_png(root / "vignette.png", np.full((H + 2, W), 100, dtype=np.uint8))
    msg = _expect(CalibrationError, root / "vignette.png", None,
                  lambda: open_dataset(f"tum-mono:{root}"))
    assert f"{W}x{H + 2}" in msg
    (root / "vignette.png").unlink()
    # camera.txt for another size.
    (root / "camera.txt").write_text("Pinhole 50.0 50.0 31.5 23.5 0\n640 480\n")
    msg = _expect(CalibrationError, root / "camera.txt", 2, lambda: open_dataset(f"tum-mono:{root}"))
    assert "for 640x480 images but" in msg and f"is {W}x{H}" in msg and "--calib FILE" in msg


def test_tum_mono_zip_undecodable_member(tmp_path: Path) -> None:
    root = make_tum_mono(tmp_path / "seq", zipped=True)
    with zipfile.ZipFile(root / "images.zip", "a") as zf:
        zf.writestr("00004.png", b"garbage")
    with (root / "times.txt").open("a") as fh:
        fh.write("00004 1399381434.0 12.0\n")
    ds = open_dataset(root)
    assert len(ds.frames) == 5
    with pytest.raises(DatasetFormatError, match="00004.png: image cannot be decoded"):
        ds.frames[4].load()


# ------------------------------------------------------------------------------------------------
# KITTI


def _kitti_poses(n: int) -> np.ndarray:
    out = np.zeros((n, 3, 4))
    for k in range(n):
        out[k, :, :3] = SO3.exp(np.array([0.0, 0.05 * k, 0.0])).matrix()
        out[k, :, 3] = [0.01 * k, -0.002 * k, 0.8 * k]
    return out


def make_kitti(seq: Path, n: int = 5, poses_beside: bool = True) -> Path:
    for k in range(n):
        _write_png(seq / "image_0" / f"{k:06d}.png", _image(k))
    (seq / "times.txt").write_text("".join(f"{0.1037359 * k:.6e}\n" for k in range(n)))
    P0 = [700.0, 0, 31.0, 0, 0, 700.0, 23.0, 0, 0, 0, 1, 0]
    (seq / "calib.txt").write_text("P0: " + " ".join(f"{v:.12e}" for v in P0) + "\n")
    text = "".join(" ".join(f"{v:.6e}" for v in m.reshape(-1)) + "\n" for m in _kitti_poses(n))
    if poses_beside:
        (seq / "poses.txt").write_text(text)
    else:
        poses_dir = seq.parent.parent / "poses"
        poses_dir.mkdir(parents=True, exist_ok=True)
        (poses_dir / f"{seq.name}.txt").write_text(text)
    return seq


@pytest.mark.parametrize("poses_beside", [True, False])
def test_kitti(tmp_path: Path, poses_beside: bool) -> None:
    seq = make_kitti(tmp_path / "sequences" / "07", poses_beside=poses_beside)
    assert detect_kind(seq) == "kitti"
    ds = open_dataset(seq)
    assert ds.kind == "kitti" and len(ds.frames) == 5
    assert ds.frames[2].t_ns == 207_471_800
    np.testing.assert_array_equal(ds.frames[4].load(), _image(4))
    assert ds.camera is not None and (ds.camera.width, ds.camera.height) == (W, H)
    assert ds.camera.fx == 700.0
    assert ds.groundtruth is not None and ds.groundtruth_frame == "cam"
    np.testing.assert_allclose(ds.groundtruth.positions_m[-1], [0.04, -0.008, 3.2])
    np.testing.assert_allclose(ds.groundtruth.stamps_s, [f.t_s for f in ds.frames])
    assert ds.imu is None and list(ds.stream()) == list(ds.frames)


def test_kitti_bad_times(tmp_path: Path) -> None:
    seq = make_kitti(tmp_path / "00")
    times = seq / "times.txt"
    times.write_text("0.0\n0.1\n0.2\n")
    msg = _expect(DatasetFormatError, times, None, lambda: open_dataset(f"kitti:{seq}"))
    assert "3 times for 5 images" in msg
    times.write_text("0.0\n0.1\n0.05\n0.3\n0.4\n")
    _expect(DatasetFormatError, times, 3, lambda: open_dataset(f"kitti:{seq}"))
    times.write_text("0.0\n0.1\n0.2 0.3\n0.3\n0.4\n")
    _expect(DatasetFormatError, times, 3, lambda: open_dataset(f"kitti:{seq}"))
    times.write_text("0.0\n0.1\n0.2\n0.3\n0.4\n")
    poses = seq / "poses.txt"
    poses.write_text("\n".join(poses.read_text().splitlines()[:4]) + "\n")
    msg = _expect(DatasetFormatError, poses, None, lambda: open_dataset(f"kitti:{seq}"))
    assert "4 poses" in msg


# ------------------------------------------------------------------------------------------------
# Plain folder


@pytest.mark.parametrize("unit", ["ns", "s"])
def test_folder_with_imu_and_camchain(tmp_path: Path, unit: str) -> None:
    root = tmp_path / "recording"
    names = []
    for k in range(3):
        names.append(f"img_{k}.png")
        _write_png(root / "images" / names[-1], _image(k))
    if unit == "ns":
        text = "timestamp [ns],filename\n" + "".join(
            f"{T0 + k * FRAME_DT},{names[k]}\n" for k in range(3))
    else:
        text = "filename,t_s\n" + "".join(f"{names[k]},{12.5 + 0.05 * k:.2f}\n" for k in range(3))
    (root / "timestamps.csv").write_text(text)
    vals = _imu_values(4)
    t_imu = [T0 + i * IMU_DT for i in range(4)] if unit == "ns" else [
        12_500_000_000 + i * IMU_DT for i in range(4)]
    (root / "imu.csv").write_text(
        "#timestamp [ns],wx,wy,wz,ax,ay,az\n"
        + "".join(f"{t_imu[i]}," + ",".join(map(repr, vals[i].tolist())) + "\n" for i in range(4))
    )
    (root / "camchain.yaml").write_text(
        "cam0:\n  camera_model: pinhole\n  distortion_coeffs: [0.0, 0.0, 0.0, 0.0]\n"
        "  distortion_model: radtan\n  intrinsics: [40.0, 40.0, 32.0, 24.0]\n"
        f"  resolution: [{W}, {H}]\n"
    )
    assert detect_kind(root) == "folder"
    ds = open_dataset(root)
    assert ds.kind == "folder" and len(ds.frames) == 3
    base = T0 if unit == "ns" else 12_500_000_000
    assert [f.t_ns for f in ds.frames] == [base + k * FRAME_DT for k in range(3)]
    np.testing.assert_array_equal(ds.frames[2].load(), _image(2))
    assert ds.imu is not None
    np.testing.assert_array_equal(ds.imu.accel_m_s2, vals[:, 3:])
    assert ds.camera is not None and ds.camera.fx == 40.0 and ds.T_body_cam is None
    assert [type(x) for x in ds.stream()][:2] == [ImuSample, Frame]


def test_folder_bad_header_and_missing_folder(tmp_path: Path) -> None:
    root = tmp_path / "rec"
    _write_png(root / "a.png", _image(0))
    (root / "timestamps.csv").write_text("stamp,name\n1,a.png\n")
    msg = _expect(DatasetFormatError, root / "timestamps.csv", 1, lambda: open_dataset(root))
    assert "lacks" in msg
    (root / "timestamps.csv").unlink()
    _expect(DatasetFormatError, root, None, lambda: open_dataset(f"folder:{root}"))
    _expect(DatasetFormatError, tmp_path / "nope", None, lambda: open_dataset(tmp_path / "nope"))


# ------------------------------------------------------------------------------------------------
# Small pieces


def test_parse_spec_and_seconds() -> None:
    assert parse_spec("kitti:/a/b") == ("kitti", Path("/a/b"))
    assert parse_spec("/a/b") == (None, Path("/a/b"))
    assert parse_spec("weird:/a") == (None, Path("weird:/a"))
    assert seconds_to_ns("1403715273.262142976") == 1403715273262142976
    assert seconds_to_ns("1.037359e-01") == 103735900
    assert seconds_to_ns("-0.5") == -500_000_000
    assert seconds_to_ns("2") == 2_000_000_000
    with pytest.raises(ValueError):
        seconds_to_ns("abc")


def test_dataset_rejects_unordered_frames(tmp_path: Path) -> None:
    frames = (Frame(10, 0, tmp_path / "a.png"), Frame(5, 1, tmp_path / "b.png"))
    with pytest.raises(DatasetFormatError):
        Dataset(kind="folder", root=tmp_path, frames=frames)


def test_cli_reports_a_bad_dataset_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from amrvio.cli.main import main

    root = make_euroc(tmp_path / "seq")
    csv = root / "mav0" / "cam0" / "data.csv"
    _replace_line(csv, 3, f"{T0 - 1},{T0 + FRAME_DT}.png")
    rc = main(["info", f"euroc:{root}"])
    err = capsys.readouterr().err
    assert rc == 1
    assert err.count("\n") == 1 and "Traceback" not in err
    assert f"{csv}:3:" in err and "backwards" in err


def test_malformed_first_line_is_not_taken_for_a_header(tmp_path: Path) -> None:
    seq = make_kitti(tmp_path / "00")
    times = seq / "times.txt"
    times.write_text("abc\n0.1\n0.2\n0.3\n0.4\n")
    _expect(DatasetFormatError, times, 1, lambda: open_dataset(f"kitti:{seq}"))
    root = make_euroc(tmp_path / "seq")
    imu = root / "mav0" / "imu0" / "data.csv"
    lines = imu.read_text().splitlines()
    imu.write_text("\n".join([f"{T0}x,0.1,0.2,0.3,9.8,0,0", *lines[2:]]) + "\n")
    _expect(DatasetFormatError, imu, 1, lambda: open_dataset(f"euroc:{root}"))
