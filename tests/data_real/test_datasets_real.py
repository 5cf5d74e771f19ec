"""Dataset readers on the real sequences in ../shared/data (skipped when absent)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from amrvio.errors import CalibrationError
from amrvio.io.dataset import detect_kind, open_dataset
from amrvio.types.camera import RadTanCamera
from amrvio.types.sensors import Frame, ImuSample
from tests.skip_policy import skip_shared_missing

pytestmark = pytest.mark.real_data

EUROC = "euroc_V1_01_easy_first95"
KITTI = "kitti00_0000-0199"
PHONE = "phone_handheld_blur_0450-0549"


def _folder(shared_data: Path, name: str) -> Path:
    path = shared_data / name
    if not path.is_dir():
        skip_shared_missing(path)
    return path


def test_euroc_v1_01_first95(shared_data: Path) -> None:
    root = _folder(shared_data, EUROC)
    assert detect_kind(root) == "euroc"
    ds = open_dataset(root)
    assert ds.kind == "euroc"
    assert len(ds.frames) == 95
    assert ds.frames[0].t_ns == 1403715273262142976
    assert ds.frames[0].path is not None and ds.frames[0].path.name == "1403715273262142976.png"
    img = ds.frames[94].load()
    assert img.shape == (480, 752) and img.dtype == np.uint8
    # IMU for the whole 145.6 s flight, exact first sample.
    assert ds.imu is not None and len(ds.imu) == 29120
    assert int(ds.imu.stamps_ns[0]) == 1403715273262142976
    assert int(ds.imu.stamps_ns[-1]) == 1403715418857143040
    np.testing.assert_array_equal(
        ds.imu.gyro_rad_s[0], [-0.0020943951023931952, 0.017453292519943295, 0.07749261878854824]
    )
    np.testing.assert_array_equal(
        ds.imu.accel_m_s2[0], [9.0874956666666655, 0.13075533333333333, -3.6938381666666662]
    )
    assert ds.imu_noise is not None and ds.imu_noise.gyro_noise_density == 1.6968e-04
    # Ground truth: first row of state_groundtruth_estimate0/data.csv.
    gt = ds.groundtruth
    assert gt is not None and ds.groundtruth_frame == "body"
    assert len(gt) == 2895
    assert gt.stamps_s[0] == pytest.approx(1403715273.262142976, abs=1e-6)
    np.testing.assert_allclose(gt.positions_m[0], [0.878895, 2.1834, 0.948427])
    q = np.array([0.069433, -0.824237, -0.106942, -0.551702])
    np.testing.assert_allclose(gt.quats_wxyz[0], q / np.linalg.norm(q), atol=1e-12)
    # Calibration.
    assert isinstance(ds.camera, RadTanCamera)
    assert ds.camera.fx == 458.654 and (ds.camera.width, ds.camera.height) == (752, 480)
    assert ds.T_body_cam is not None
    np.testing.assert_allclose(
        ds.T_body_cam.t, [-0.0216401454975, -0.064676986768, 0.00981073058949]
    )
    # Photometric files found in photometric_calib_estimated_dsso/.
    assert ds.inverse_response is not None and ds.inverse_response.shape == (256,)
    assert ds.vignette is not None and ds.vignette.shape == (480, 752)
    # The merged stream is time ordered and holds everything once.
    stamps = np.array([it.t_ns for it in ds.stream()], dtype=np.int64)
    assert stamps.shape[0] == 95 + 29120
    assert np.all(np.diff(stamps) >= 0)
    first = list(ds.stream())[:2]
    assert isinstance(first[0], ImuSample) and isinstance(first[1], Frame)
    assert first[0].t_ns == first[1].t_ns


def test_kitti00_first200(shared_data: Path) -> None:
    root = _folder(shared_data, KITTI)
    assert detect_kind(root) == "kitti"
    ds = open_dataset(f"kitti:{root}")
    assert len(ds.frames) == 200
    assert ds.frames[0].load().shape == (376, 1241)
    assert ds.camera is not None and (ds.camera.width, ds.camera.height) == (1241, 376)
    assert ds.camera.fx == 718.856 and ds.camera.cx == 607.1928
    times = np.loadtxt(root / "times.txt")
    np.testing.assert_allclose([f.t_s for f in ds.frames], times, atol=1e-9)
    assert ds.frames[1].t_ns == 103_735_900
    gt = ds.groundtruth
    assert gt is not None and len(gt) == 200 and ds.groundtruth_frame == "cam"
    last = np.loadtxt(root / "poses.txt")[-1].reshape(3, 4)
    np.testing.assert_allclose(gt.positions_m[-1], last[:, 3], atol=1e-12)
    np.testing.assert_allclose(gt.positions_m[-1], [52.95984, -5.197886, 89.59271])
    assert ds.imu is None


def test_phone_sensor_yaml_is_wrong_and_calib_override_works(shared_data: Path) -> None:
    root = _folder(shared_data, PHONE)
    assert detect_kind(root) == "euroc"
    sensor_yaml = root / "mav0" / "cam0" / "sensor.yaml"
    with pytest.raises(CalibrationError) as info:
        open_dataset(root)
    err = info.value
    assert Path(err.path) == sensor_yaml and err.line is not None
    assert "640x480" in str(err) and "1920x1080" in str(err) and "\n" not in str(err)

    ds = open_dataset(root, calib=root / "calib_claimed" / "live.yaml")
    assert len(ds.frames) == 100
    assert ds.frames[0].path is not None and ds.frames[0].path.name.startswith("0")
    assert ds.frames[0].t_ns == 1764757990480654336
    assert ds.frames[-1].t_ns == 1764757996880467968
    assert isinstance(ds.camera, RadTanCamera)
    assert (ds.camera.width, ds.camera.height) == (1920, 1080)
    assert ds.camera.fx == pytest.approx(876.58388117)
    assert ds.camera.cy == pytest.approx(527.50461067)
    assert ds.camera.distortion[:4] == pytest.approx((-0.0212738, 0.05926712, -0.00043674,
                                                      0.00102205))
    assert ds.imu is None and ds.groundtruth is None
    assert ds.frames[50].load().shape == (1080, 1920)


def test_info_on_the_real_sequences(shared_data: Path, tmp_path: Path,
                                    capsys: pytest.CaptureFixture[str]) -> None:
    import json

    from amrvio.cli.main import main

    out = tmp_path / "info.json"
    euroc = _folder(shared_data, EUROC)
    assert main(["info", str(euroc), "--json", str(out)]) == 0
    js = json.loads(out.read_text())
    assert js["kind"] == "euroc" and js["frames"]["count"] == 95
    assert js["frames"]["rate_hz"] == pytest.approx(20.0, abs=1e-3)
    assert (js["frames"]["width"], js["frames"]["height"]) == (752, 480)
    assert js["imu"]["samples"] == 29120 and js["imu"]["rate_hz"] == pytest.approx(200.0, abs=0.01)
    assert js["imu"]["duration_s"] == pytest.approx(145.595, abs=1e-3)
    assert js["groundtruth"]["path_length_m"] == pytest.approx(58.35, abs=0.05)  # MANIFEST
    assert js["camera"]["fx"] == 458.654 and js["imu_noise"]["accel_noise_density"] == 2.0e-3
    assert js["photometric"] == {"inverse_response": True, "vignette": True}

    kitti = _folder(shared_data, KITTI)
    assert main(["info", f"kitti:{kitti}", "--json", str(out)]) == 0
    js = json.loads(out.read_text())
    assert js["frames"]["count"] == 200 and js["frames"]["rate_hz"] == pytest.approx(9.65, abs=0.01)
    assert js["groundtruth"]["path_length_m"] == pytest.approx(145.0, abs=3.0)  # README: 145 m

    phone = _folder(shared_data, PHONE)
    capsys.readouterr()
    assert main(["info", str(phone)]) == 1  # its sensor.yaml claims 640x480
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "sensor.yaml:" in err and "1920x1080" in err
    assert main(["info", str(phone), "--calib", str(phone / "calib_claimed" / "live.yaml"),
                 "--json", str(out)]) == 0
    js = json.loads(out.read_text())
    assert js["frames"]["rate_hz"] == pytest.approx(15.6, abs=0.2) and js["imu"] is None
