"""Calibration readers on the real sequences in ../shared/data (skipped when absent)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from amrvio.errors import CalibrationError
from amrvio.io.calib import (
    check_image_size,
    read_dso_camera,
    read_euroc_camera,
    read_euroc_imu,
    read_kitti_calib,
    read_pcalib,
    read_vignette,
)
from amrvio.types.camera import RadTanCamera
from tests.skip_policy import skip_shared_missing

pytestmark = pytest.mark.real_data


def _first_image(folder: Path) -> Path:
    images = sorted(folder.glob("*.png"))
    if not images:
        skip_shared_missing(f"no *.png in {folder}")
    return images[0]


def _shape(path: Path) -> tuple[int, ...]:
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert img is not None, path
    return tuple(img.shape)


def test_euroc_cam0_sensor_yaml(shared_data: Path) -> None:
    cam0 = shared_data / "euroc_V1_01_easy_first95" / "mav0" / "cam0"
    calib = read_euroc_camera(cam0 / "sensor.yaml")
    cam = calib.camera
    assert isinstance(cam, RadTanCamera)
    assert (cam.fx, cam.fy, cam.cx, cam.cy) == (458.654, 457.296, 367.215, 248.375)
    assert cam.distortion == (-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05, 0.0)
    assert (cam.width, cam.height) == (752, 480)
    assert calib.rate_hz == 20.0
    np.testing.assert_allclose(
        calib.T_body_cam.t, [-0.0216401454975, -0.064676986768, 0.00981073058949], atol=1e-15
    )
    # T_BS row-major: the camera x axis is the first column, nearly the body y axis
    np.testing.assert_allclose(
        calib.T_body_cam.rot.act(np.array([1.0, 0.0, 0.0])),
        [0.0148655429818, 0.999557249008, -0.0257744366974],
        atol=1e-9,
    )
    check_image_size(cam, _shape(_first_image(cam0 / "data")), cam0 / "sensor.yaml", cam0)


def test_euroc_imu0_sensor_yaml(shared_data: Path) -> None:
    noise = read_euroc_imu(shared_data / "euroc_V1_01_easy_first95" / "mav0" / "imu0" / "sensor.yaml")
    assert noise.gyro_noise_density == 1.6968e-04
    assert noise.gyro_random_walk == 1.9393e-05
    assert noise.accel_noise_density == 2.0e-3
    assert noise.accel_random_walk == 3.0e-3
    assert noise.rate_hz == 200.0


def test_euroc_photometric_files(shared_data: Path) -> None:
    folder = shared_data / "euroc_V1_01_easy_first95" / "photometric_calib_estimated_dsso"
    g = read_pcalib(folder / "pcalib.txt")  # has the trailing vis_exponent line
    assert g.shape == (256,)
    assert np.all(np.diff(g) > 0)
    assert g[0] == 0.0 and g[-1] == 255.0
    vig = read_vignette(folder / "vignette.png")
    assert vig.shape == (480, 752)
    assert vig.max() == 1.0 and 0.5 < vig.min() < 1.0  # raw 16-bit min/max = 52416/65535
    np.testing.assert_allclose(vig.min(), 52416 / 65535)


def test_euroc_dso_camera_txt_matches_sensor_yaml(shared_data: Path) -> None:
    root = shared_data / "euroc_V1_01_easy_first95"
    dso = read_dso_camera(root / "photometric_calib_estimated_dsso" / "cameraLeft.txt")
    yaml_cam = read_euroc_camera(root / "mav0" / "cam0" / "sensor.yaml").camera
    assert dso.camera == yaml_cam
    assert dso.output_mode == "manual" and dso.output_size == (752, 480)


def test_kitti_calib(shared_data: Path) -> None:
    seq = shared_data / "kitti00_0000-0199"
    height, width = _shape(_first_image(seq / "image_0"))[:2]
    cam = read_kitti_calib(seq / "calib.txt", width, height)
    assert (cam.fx, cam.fy, cam.cx, cam.cy) == (718.856, 718.856, 607.1928, 185.2157)
    assert (cam.width, cam.height) == (1241, 376)


def test_phone_calibration_mismatch_is_reported(shared_data: Path) -> None:
    cam0 = shared_data / "phone_handheld_blur_0450-0549" / "mav0" / "cam0"
    # this sensor.yaml is not valid YAML ("rows: 4 cols: 4 dt: d" on line 3)
    with pytest.raises(CalibrationError) as info:
        read_euroc_camera(cam0 / "sensor.yaml")
    assert info.value.line == 3 and "sensor.yaml:3:" in str(info.value)
    # and the size it claims (640x480) is not the images' size
    claimed = RadTanCamera(640, 480, 458.654, 457.296, 367.215, 248.375, 0.0, 0.0, 0.0, 0.0)
    image = _first_image(cam0 / "data")
    with pytest.raises(CalibrationError) as info:
        check_image_size(claimed, _shape(image), cam0 / "sensor.yaml", image)
    assert "640x480" in str(info.value) and "1920x1080" in str(info.value)
