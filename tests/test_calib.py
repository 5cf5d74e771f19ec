"""Calibration readers and writers on small files written here, including malformed ones."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from amrvio.errors import CalibrationError, ShapeError
from amrvio.io.calib import (
    CameraCalib,
    DsoCameraCalib,
    check_image_size,
    read_dso_camera,
    read_euroc_camera,
    read_euroc_imu,
    read_euroc_sensor_T_BS,
    read_kalibr_camchain,
    read_kalibr_imu,
    read_kitti_calib,
    read_pcalib,
    read_vignette,
    write_dso_camera,
    write_euroc_camera,
    write_euroc_imu,
    write_kalibr_camchain,
    write_kalibr_imu,
    write_pcalib,
    write_vignette,
)
from amrvio.types.camera import EquidistantCamera, FovCamera, PinholeCamera, RadTanCamera
from amrvio.types.lie import SE3
from amrvio.types.sensors import ImuNoise

EUROC_CAM = RadTanCamera(
    752, 480, 458.654, 457.296, 367.215, 248.375, -0.28340811, 0.07395907, 0.00019359, 1.76187114e-05
)
FISHEYE = EquidistantCamera(512, 512, 190.97, 190.97, 254.93, 256.90, 0.0034, 0.0007, -0.002, 0.0002)
FOV = FovCamera(1280, 1024, 446.9, 447.1, 630.7, 510.5, 0.933271)

# Kalibr output for TUM-VI-like cam0 (layout as written by kalibr_calibrate_imu_camera)
KALIBR_CAMCHAIN = """\
cam0:
  T_cam_imu:
  - [-0.9995001916372802, -0.030276890307052547, -0.00909268004357788, 0.04794907203]
  - [0.010891990149369226, -0.05980406807002536, -0.9981507090579367, -0.047162106]
  - [0.029677120271788763, -0.9977508623677608, 0.06010395308765726, -0.0504829]
  - [0.0, 0.0, 0.0, 1.0]
  cam_overlaps: [1]
  camera_model: pinhole
  distortion_coeffs: [0.0034823894022493434, 0.0007150348452162257, -0.0020532361418706202,
    0.00020293673591811182]
  distortion_model: equidistant
  intrinsics: [190.97847715128717, 190.9733070521226, 254.93170605935475, 256.8974428996504]
  resolution: [512, 512]
  rostopic: /cam0/image_raw
  timeshift_cam_imu: 0.0021
"""

EUROC_CAM_YAML = """\
%YAML:1.0
# General sensor definitions.
sensor_type: camera
comment: VI-Sensor cam0 (MT9M034)

# Sensor extrinsics wrt. the body-frame.
T_BS:
  cols: 4
  rows: 4
  data: [0.0148655429818, -0.999880929698, 0.00414029679422, -0.0216401454975,
         0.999557249008, 0.0149672133247, 0.025715529948, -0.064676986768,
        -0.0257744366974, 0.00375618835797, 0.999660727178, 0.00981073058949,
         0.0, 0.0, 0.0, 1.0]

# Camera specific definitions.
rate_hz: 20
resolution: [752, 480]
camera_model: pinhole
intrinsics: [458.654, 457.296, 367.215, 248.375] #fu, fv, cu, cv
distortion_model: radial-tangential
distortion_coefficients: [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]
"""

EUROC_IMU_YAML = """\
%YAML:1.0
sensor_type: imu
comment: VI-Sensor IMU (ADIS16448)
T_BS:
  cols: 4
  rows: 4
  data: [1.0, 0.0, 0.0, 0.0,
         0.0, 1.0, 0.0, 0.0,
         0.0, 0.0, 1.0, 0.0,
         0.0, 0.0, 0.0, 1.0]
rate_hz: 200

gyroscope_noise_density: 1.6968e-04     # [ rad / s / sqrt(Hz) ]
gyroscope_random_walk: 1.9393e-05       # [ rad / s^2 / sqrt(Hz) ]
accelerometer_noise_density: 2.0000e-3  # [ m / s^2 / sqrt(Hz) ]
accelerometer_random_walk: 3.0000e-3    # [ m / s^3 / sqrt(Hz) ]
"""

KITTI_CALIB = """\
P0: 7.188560000000e+02 0.000000000000e+00 6.071928000000e+02 0.000000000000e+00 \
0.000000000000e+00 7.188560000000e+02 1.852157000000e+02 0.000000000000e+00 \
0.000000000000e+00 0.000000000000e+00 1.000000000000e+00 0.000000000000e+00
P1: 7.188560000000e+02 0.000000000000e+00 6.071928000000e+02 -3.861448000000e+02 \
0.000000000000e+00 7.188560000000e+02 1.852157000000e+02 0.000000000000e+00 \
0.000000000000e+00 0.000000000000e+00 1.000000000000e+00 0.000000000000e+00
Tr: 4.276802385584e-04 -9.999672484946e-01 -8.084491683471e-03 -1.198459927713e-02 \
-7.210626507497e-03 8.081198471645e-03 -9.999413164504e-01 -5.403984729748e-02 \
9.999738645903e-01 4.859485810390e-04 -7.206933692422e-03 -2.921968648686e-01
"""


def _write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def _error(fn: object, *args: object) -> CalibrationError:
    with pytest.raises(CalibrationError) as info:
        fn(*args)  # type: ignore[operator]
    err = info.value
    assert "\n" not in str(err)
    return err


def _T(seed: int) -> SE3:
    return SE3.exp(np.random.default_rng(seed).normal(size=6))


# ----- Kalibr -----------------------------------------------------------------------------------


def test_kalibr_camchain_equidistant(tmp_path: Path) -> None:
    calib = read_kalibr_camchain(_write(tmp_path, "camchain.yaml", KALIBR_CAMCHAIN))
    cam = calib.camera
    assert isinstance(cam, EquidistantCamera)
    assert (cam.width, cam.height) == (512, 512)
    assert cam.fx == 190.97847715128717 and cam.cy == 256.8974428996504
    assert cam.k4 == 0.00020293673591811182
    assert calib.T_cam_imu is not None
    assert calib.T_cam_imu.t == pytest.approx([0.04794907203, -0.047162106, -0.0504829], abs=1e-15)
    assert calib.timeshift_cam_imu_s == 0.0021


def test_kalibr_camchain_round_trip(tmp_path: Path) -> None:
    for calib in (
        CameraCalib(EUROC_CAM, _T(1), 0.0),
        CameraCalib(FISHEYE, None, -0.013),
        CameraCalib(EUROC_CAM.pinhole(), _T(2)),
        CameraCalib(FOV, _T(5)),
    ):
        path = tmp_path / "camchain.yaml"
        write_kalibr_camchain(path, calib)
        back = read_kalibr_camchain(path)
        assert back.camera == calib.camera
        assert back.timeshift_cam_imu_s == calib.timeshift_cam_imu_s
        if calib.T_cam_imu is None:
            assert back.T_cam_imu is None
        else:
            assert back.T_cam_imu is not None
            np.testing.assert_allclose(back.T_cam_imu.matrix(), calib.T_cam_imu.matrix(), atol=1e-15)
    with pytest.raises(ShapeError):
        write_kalibr_camchain(tmp_path / "k3.yaml", CameraCalib(RadTanCamera(10, 10, 1, 1, 5, 5, 0, 0, 0, 0, 0.1)))


def test_kalibr_camchain_other_camera_and_errors(tmp_path: Path) -> None:
    two = KALIBR_CAMCHAIN + KALIBR_CAMCHAIN.replace("cam0:", "cam1:").replace("[512, 512]", "[640, 512]")
    path = _write(tmp_path, "two.yaml", two)
    assert read_kalibr_camchain(path, "cam1").camera.width == 640
    err = _error(read_kalibr_camchain, path, "cam2")
    assert "two.yaml" in str(err) and "cam2" in str(err)

    missing = KALIBR_CAMCHAIN.replace("  intrinsics:", "  intrinsix:")
    err = _error(read_kalibr_camchain, _write(tmp_path, "missing.yaml", missing))
    assert "missing.yaml" in str(err) and "intrinsics" in str(err)

    short = KALIBR_CAMCHAIN.replace("  resolution: [512, 512]", "  resolution: [512]")
    err = _error(read_kalibr_camchain, _write(tmp_path, "short.yaml", short))
    assert err.line == 13 and "short.yaml:13:" in str(err)

    text = KALIBR_CAMCHAIN.replace("190.9733070521226", "abc")
    err = _error(read_kalibr_camchain, _write(tmp_path, "text.yaml", text))
    assert err.line == 12 and "'abc' is not a number" in str(err)

    nan = KALIBR_CAMCHAIN.replace("190.9733070521226", ".nan")
    assert "not finite" in str(_error(read_kalibr_camchain, _write(tmp_path, "nan.yaml", nan)))

    bad_rot = KALIBR_CAMCHAIN.replace("-0.9995001916372802", "-0.9")
    err = _error(read_kalibr_camchain, _write(tmp_path, "rot.yaml", bad_rot))
    assert "not orthonormal" in str(err) and err.line == 2

    three_rows = KALIBR_CAMCHAIN.replace("  - [0.0, 0.0, 0.0, 1.0]\n", "")
    _error(read_kalibr_camchain, _write(tmp_path, "rows.yaml", three_rows))

    bad_row = KALIBR_CAMCHAIN.replace("  - [0.0, 0.0, 0.0, 1.0]", "  - [0.0, 0.0, 0.1, 1.0]")
    assert "last row" in str(_error(read_kalibr_camchain, _write(tmp_path, "row.yaml", bad_row)))

    fov = KALIBR_CAMCHAIN.replace("distortion_model: equidistant", "distortion_model: fov")
    err = _error(read_kalibr_camchain, _write(tmp_path, "fov.yaml", fov))
    assert "fov distortion takes 1 coefficients, got 4" in str(err) and err.line == 9
    ds = KALIBR_CAMCHAIN.replace("distortion_model: equidistant", "distortion_model: ds")
    err = _error(read_kalibr_camchain, _write(tmp_path, "ds.yaml", ds))
    assert "'ds' is not supported" in str(err) and err.line == 11

    omni = KALIBR_CAMCHAIN.replace("camera_model: pinhole", "camera_model: omni")
    assert "omni" in str(_error(read_kalibr_camchain, _write(tmp_path, "omni.yaml", omni)))

    wrong_count = KALIBR_CAMCHAIN.replace("-0.0020532361418706202,\n", "")
    _error(read_kalibr_camchain, _write(tmp_path, "count.yaml", wrong_count))

    err = _error(read_kalibr_camchain, _write(tmp_path, "syntax.yaml", "cam0:\n  a: [1, 2\n  b: 3\n"))
    assert "invalid YAML" in str(err) and err.line is not None

    _error(read_kalibr_camchain, _write(tmp_path, "list.yaml", "- 1\n- 2\n"))
    _error(read_kalibr_camchain, _write(tmp_path, "scalar_cam.yaml", "cam0: 3\n"))
    assert "file not found" in str(_error(read_kalibr_camchain, tmp_path / "nope.yaml"))


def test_kalibr_imu_flat_nested_and_round_trip(tmp_path: Path) -> None:
    flat = """\
#Accelerometers
accelerometer_noise_density: 2.0e-3   #Noise density (continuous-time)
accelerometer_random_walk:   3.0e-3   #Bias random walk
#Gyroscopes
gyroscope_noise_density:     1.6968e-04   #Noise density (continuous-time)
gyroscope_random_walk:       1.9393e-05   #Bias random walk
rostopic:                    /imu0      #the IMU ROS topic
update_rate:                 200.0      #Hz (for discretization of the values above)
"""
    noise = read_kalibr_imu(_write(tmp_path, "imu.yaml", flat))
    assert noise == ImuNoise.euroc_adis16448()

    nested = "imu0:\n" + "".join("  " + line + "\n" for line in flat.splitlines())
    assert read_kalibr_imu(_write(tmp_path, "imu_nested.yaml", nested)) == noise

    custom = ImuNoise(1.1e-3, 2.2e-5, 3.3e-2, 4.4e-4, 400.0)
    write_kalibr_imu(tmp_path / "out.yaml", custom)
    assert read_kalibr_imu(tmp_path / "out.yaml") == custom

    missing = flat.replace("update_rate", "rate")
    err = _error(read_kalibr_imu, _write(tmp_path, "m.yaml", missing))
    assert "update_rate" in str(err) and "m.yaml" in str(err)
    neg = flat.replace("1.9393e-05", "-1.9393e-05")
    assert _error(read_kalibr_imu, _write(tmp_path, "neg.yaml", neg)).line == 6
    word = flat.replace("2.0e-3", "two")
    assert _error(read_kalibr_imu, _write(tmp_path, "w.yaml", word)).line == 2
    # PyYAML reads "2e-3" (no dot) as a string; we accept it as a number
    nodot = flat.replace("2.0e-3", "2e-3")
    assert read_kalibr_imu(_write(tmp_path, "nodot.yaml", nodot)).accel_noise_density == 2e-3


# ----- EuRoC ------------------------------------------------------------------------------------


def test_euroc_camera_yaml(tmp_path: Path) -> None:
    calib = read_euroc_camera(_write(tmp_path, "sensor.yaml", EUROC_CAM_YAML))
    assert calib.camera == EUROC_CAM
    assert calib.rate_hz == 20.0
    np.testing.assert_allclose(
        calib.T_body_cam.t, [-0.0216401454975, -0.064676986768, 0.00981073058949], atol=1e-15
    )
    # T_BS maps camera points into the body frame: the camera's z axis in the body frame
    np.testing.assert_allclose(
        calib.T_body_cam.rot.act(np.array([0.0, 0.0, 1.0])),
        [0.00414029679422, 0.025715529948, 0.999660727178],
        atol=1e-9,
    )
    cc = calib.to_camera_calib()
    assert cc.T_cam_imu is not None
    np.testing.assert_allclose(
        cc.T_cam_imu.matrix(), np.linalg.inv(calib.T_body_cam.matrix()), atol=1e-12
    )
    np.testing.assert_allclose(
        read_euroc_sensor_T_BS(tmp_path / "sensor.yaml").matrix(), calib.T_body_cam.matrix()
    )


def test_euroc_writers_round_trip(tmp_path: Path) -> None:
    for cam in (EUROC_CAM, FISHEYE, FOV, EUROC_CAM.pinhole()):
        T = _T(3)
        write_euroc_camera(tmp_path / "cam.yaml", cam, T, 30.0, comment="test cam")
        back = read_euroc_camera(tmp_path / "cam.yaml")
        assert back.camera == cam and back.rate_hz == 30.0
        np.testing.assert_allclose(back.T_body_cam.matrix(), T.matrix(), atol=1e-15)
        assert (tmp_path / "cam.yaml").read_text().startswith("%YAML:1.0\n")
    noise = ImuNoise(1e-4, 2e-5, 3e-3, 4e-4, 100.0)
    T = _T(4)
    write_euroc_imu(tmp_path / "imu.yaml", noise, T)
    assert read_euroc_imu(tmp_path / "imu.yaml") == noise
    np.testing.assert_allclose(read_euroc_sensor_T_BS(tmp_path / "imu.yaml").matrix(), T.matrix(), atol=1e-15)
    write_euroc_imu(tmp_path / "imu2.yaml", noise)
    np.testing.assert_allclose(read_euroc_sensor_T_BS(tmp_path / "imu2.yaml").matrix(), np.eye(4))


def test_euroc_imu_yaml(tmp_path: Path) -> None:
    noise = read_euroc_imu(_write(tmp_path, "imu.yaml", EUROC_IMU_YAML))
    assert noise == ImuNoise.euroc_adis16448()
    _error(read_euroc_imu, _write(tmp_path, "cam.yaml", EUROC_CAM_YAML))  # sensor_type camera
    _error(read_euroc_camera, tmp_path / "imu.yaml")  # sensor_type imu
    nan = EUROC_IMU_YAML.replace("1.6968e-04", "nan")
    err = _error(read_euroc_imu, _write(tmp_path, "nan.yaml", nan))
    assert err.line == 13 and "nan.yaml:13:" in str(err)


def test_euroc_camera_malformed(tmp_path: Path) -> None:
    def bad(name: str, old: str, new: str) -> CalibrationError:
        assert old in EUROC_CAM_YAML
        return _error(read_euroc_camera, _write(tmp_path, name, EUROC_CAM_YAML.replace(old, new)))

    err = bad("nokey.yaml", "rate_hz: 20\n", "")
    assert "rate_hz" in str(err) and "nokey.yaml" in str(err)
    assert bad("nobs.yaml", "T_BS:", "T_XX:").problem == "missing key 'T_BS'"
    assert bad("few.yaml", "[458.654, 457.296, 367.215, 248.375]", "[458.654, 457.296, 367.215]").line == 19
    assert bad("dist.yaml", "1.76187114e-05]", "1.76187114e-05, 0.1, 0.2]").line == 21
    assert bad("word.yaml", "rate_hz: 20", "rate_hz: fast").line == 16
    assert bad("zero.yaml", "rate_hz: 20", "rate_hz: 0").line == 16
    err = bad("rot.yaml", "0.0148655429818, -0.999880929698", "0.1148655429818, -0.999880929698")
    assert "not orthonormal" in str(err) and err.line == 10
    assert bad("n15.yaml", "0.0, 0.0, 0.0, 1.0]", "0.0, 0.0, 0.0]").line == 10
    assert bad("rows.yaml", "rows: 4", "rows: 3").line == 9
    assert bad("size.yaml", "[752, 480]", "[752, 0]").line == 17
    assert "positive integer" in str(bad("sizef.yaml", "[752, 480]", "[752.5, 480]"))
    assert bad("model.yaml", "radial-tangential", "weird").line == 20
    assert bad("nanv.yaml", "367.215", ".nan").line == 19


# ----- KITTI ------------------------------------------------------------------------------------


def test_kitti_calib(tmp_path: Path) -> None:
    path = _write(tmp_path, "calib.txt", KITTI_CALIB)
    cam = read_kitti_calib(path, 1241, 376)
    assert cam == PinholeCamera(1241, 376, 718.856, 718.856, 607.1928, 185.2157)
    assert read_kitti_calib(path, 1241, 376, "P1") == cam  # same K, baseline in P[0, 3]

    first = KITTI_CALIB.splitlines()[0]
    assert "missing projection matrix 'P0'" in str(
        _error(read_kitti_calib, _write(tmp_path, "nop0.txt", KITTI_CALIB.replace("P0:", "PX:")), 1241, 376)
    )
    short = KITTI_CALIB.replace(" 1.000000000000e+00 0.000000000000e+00\nP1", " 1.000000000000e+00\nP1")
    err = _error(read_kitti_calib, _write(tmp_path, "short.txt", short), 1241, 376)
    assert err.line == 1 and "expected 12 values" in str(err) and "short.txt:1:" in str(err)
    word = "Tr: 1 2 3\n" + first.replace("6.071928000000e+02", "x607")
    err = _error(read_kitti_calib, _write(tmp_path, "word.txt", word), 1241, 376)
    assert err.line == 2 and "not a number" in str(err)
    nan = first.replace("6.071928000000e+02", "nan")
    assert "not finite" in str(_error(read_kitti_calib, _write(tmp_path, "nan.txt", nan), 1241, 376))
    skew = first.replace("7.188560000000e+02 0.000000000000e+00", "7.188560000000e+02 1.0", 1)
    assert "rectified" in str(_error(read_kitti_calib, _write(tmp_path, "skew.txt", skew), 1241, 376))
    err = _error(read_kitti_calib, _write(tmp_path, "junk.txt", first + "\njunk line\n"), 1241, 376)
    assert err.line == 2
    neg = first.replace("7.188560000000e+02", "-7.188560000000e+02", 1)
    _error(read_kitti_calib, _write(tmp_path, "neg.txt", neg), 1241, 376)
    _error(read_kitti_calib, path, 0, 376)
    _error(read_kitti_calib, tmp_path / "missing.txt", 1241, 376)


# ----- DSO camera.txt ---------------------------------------------------------------------------


def test_dso_camera_variants(tmp_path: Path) -> None:
    def read(text: str) -> DsoCameraCalib:
        return read_dso_camera(_write(tmp_path, "camera.txt", text))

    # EuRoC's DSO file: 8 bare numbers = RadTan, absolute; explicit relative output calibration
    calib = read(
        "458.654 457.296 367.215 248.375 -0.28340811 0.07395907 0.00019359 1.76187114e-05\n"
        "752 480\n0.60991 0.95270 0.48832 0.51744 0.0\n752 480\n"
    )
    assert calib.camera == EUROC_CAM
    assert calib.output_mode == "manual" and calib.output_size == (752, 480)
    assert calib.output_camera == PinholeCamera(
        752, 480, 0.60991 * 752, 0.95270 * 480, 0.48832 * 752 - 0.5, 0.51744 * 480 - 0.5
    )
    # relative pinhole: K = [fx w, fy h, cx w - 0.5, cy h - 0.5] (DSO convention)
    calib = read("Pinhole 0.5 0.6 0.5 0.5 0\n640 480\ncrop\n320 240\n")
    assert calib.camera == PinholeCamera(640, 480, 320.0, 288.0, 319.5, 239.5)
    assert (calib.output_mode, calib.output_size, calib.output_camera) == ("crop", (320, 240), None)
    calib = read("RadTan 458.654 457.296 367.215 248.375 -0.28340811 0.07395907 0.00019359 1.76187114e-05\n752 480\n")
    assert calib.camera == EUROC_CAM and calib.output_mode is None
    for name in ("EquiDistant", "KannalaBrandt"):
        calib = read(f"{name} 190.97 190.97 254.93 256.90 0.0034 0.0007 -0.002 0.0002\n512 512\nfull\n512 512\n")
        assert calib.camera == FISHEYE and calib.output_mode == "full"
    assert read("Pinhole 500 500 320 240 0\n640 480\nnone\n640 480\n").output_mode == "none"
    # TUM monoVO sequence 01: five bare numbers = FOV model, relative intrinsics
    calib = read("0.349153000000 0.436593000000 0.493140000000 0.499021000000 0.933271000000\n"
                 "1280 1024\ncrop\n640 480\n")
    assert calib.camera == FovCamera(
        1280, 1024, 0.349153 * 1280, 0.436593 * 1024, 0.49314 * 1280 - 0.5, 0.499021 * 1024 - 0.5,
        0.933271,
    )
    assert calib.output_mode == "crop" and calib.output_size == (640, 480)
    assert read("FOV 446.9 447.1 630.7 510.5 0.933271\n1280 1024\n").camera == FOV


def test_dso_camera_errors(tmp_path: Path) -> None:
    def err(text: str) -> CalibrationError:
        return _error(read_dso_camera, _write(tmp_path, "camera.txt", text))

    e = err("FOV 0.3 0.4 0.5 0.5 3.5\n1280 1024\n")
    assert "omega" in str(e) and e.line == 1 and "camera.txt:1:" in str(e)
    assert err("FOV 0.3 0.4 0.5 0.5\n1280 1024\n").line == 1
    assert err("Omni 1 2 3 4\n640 480\n").line == 1
    assert err("RadTan 500 500 320 240 0.1 0.2 0.3\n640 480\n").line == 1
    assert err("500 500 320 240 0.1 0.2\n640 480\n").line == 1
    assert err("Pinhole 500 500 320 240 0.3\n640 480\n").line == 1
    assert err("Pinhole 500 abc 320 240 0\n640 480\n").line == 1
    assert err("Pinhole 500 nan 320 240 0\n640 480\n").line == 1
    assert err("Pinhole 500 500 320 240 0\n640\n").line == 2
    assert err("Pinhole 500 500 320 240 0\n640 x\n").line == 2
    assert err("Pinhole 500 500 320 240 0\n640 -480\n").line == 2
    assert err("Pinhole 500 500 320 240 0\n640 480\ncrop\n").line == 3
    assert err("Pinhole 500 500 320 240 0\n640 480\nzoom\n640 480\n").line == 3
    assert err("Pinhole 500 500 320 240 0\n640 480\ncrop\n640\n").line == 4
    assert err("Pinhole 500 500 320 240 0\n").line is None
    assert err("\n640 480\n").line == 1


def test_dso_camera_round_trip(tmp_path: Path) -> None:
    out_cam = PinholeCamera(640, 400, 300.0, 310.0, 319.5, 199.5)
    for calib in (
        DsoCameraCalib(EUROC_CAM, "manual", (640, 400), out_cam),
        DsoCameraCalib(FISHEYE, "crop", (400, 400)),
        DsoCameraCalib(FOV, "full", (640, 480)),
        DsoCameraCalib(EUROC_CAM.pinhole()),
    ):
        write_dso_camera(tmp_path / "camera.txt", calib)
        back = read_dso_camera(tmp_path / "camera.txt")
        assert back.camera == calib.camera
        assert back.output_mode == calib.output_mode and back.output_size == calib.output_size
        if calib.output_camera is None:
            assert back.output_camera is None
        else:
            assert back.output_camera is not None
            np.testing.assert_allclose(back.output_camera.K, calib.output_camera.K, rtol=1e-14)


# ----- photometric ------------------------------------------------------------------------------


def _response() -> np.ndarray:
    x = np.arange(256, dtype=float)
    return 255.0 * (x / 255.0) ** 1.7 + 0.01 * x  # strictly increasing


def test_pcalib_round_trip_and_vis_exponent(tmp_path: Path) -> None:
    g = _response()
    write_pcalib(tmp_path / "pcalib.txt", g)
    np.testing.assert_array_equal(read_pcalib(tmp_path / "pcalib.txt"), g)
    text = " ".join(f"{v:.6f}" for v in g) + " \nvis_exponent: 1.000000\n"
    back = read_pcalib(_write(tmp_path, "euroc_pcalib.txt", text))
    np.testing.assert_allclose(back, g, atol=5e-7)
    assert back.shape == (256,) and back.dtype == np.float64
    with pytest.raises(ShapeError):
        write_pcalib(tmp_path / "x.txt", g[::-1])
    with pytest.raises(ShapeError):
        write_pcalib(tmp_path / "x.txt", g[:255])


def test_pcalib_malformed(tmp_path: Path) -> None:
    g = [f"{v:.6f}" for v in _response()]

    def err(text: str) -> CalibrationError:
        return _error(read_pcalib, _write(tmp_path, "pcalib.txt", text))

    e = err(" ".join(g[:255]) + "\n")
    assert e.line == 1 and "expected 256" in str(e) and "pcalib.txt:1:" in str(e)
    assert err("\n" + " ".join(g[:100] + ["x"] + g[101:]) + "\n").line == 2
    assert "not finite" in str(err(" ".join(g[:100] + ["nan"] + g[101:])))
    e = err(" ".join(g[:100] + [g[98]] + g[101:]))
    assert "strictly increasing" in str(e)
    assert err(" ".join(g) + "\n1 2 3\n").line == 2
    assert err("").line is None
    _error(read_pcalib, tmp_path / "missing.txt")


def test_vignette_read_write(tmp_path: Path) -> None:
    h, w = 48, 64
    yy, xx = np.mgrid[0:h, 0:w]
    vig = 1.0 - 0.6 * (((xx - w / 2) / w) ** 2 + ((yy - h / 2) / h) ** 2)
    vig /= vig.max()
    write_vignette(tmp_path / "vignette.png", 0.8 * vig)
    raw = cv2.imread(str(tmp_path / "vignette.png"), cv2.IMREAD_UNCHANGED)
    assert raw is not None
    assert raw.dtype == np.uint16 and raw.max() == 65535
    back = read_vignette(tmp_path / "vignette.png")
    assert back.shape == (h, w) and back.max() == 1.0
    np.testing.assert_allclose(back, vig, atol=1.0 / 65535)

    eight = np.round(vig * 200).astype(np.uint8)
    cv2.imwrite(str(tmp_path / "v8.png"), eight)
    np.testing.assert_allclose(read_vignette(tmp_path / "v8.png"), eight / eight.max())

    cv2.imwrite(str(tmp_path / "colour.png"), np.full((4, 4, 3), 9, np.uint8))
    assert "grey" in str(_error(read_vignette, tmp_path / "colour.png"))
    cv2.imwrite(str(tmp_path / "zero.png"), np.zeros((4, 4), np.uint8))
    assert "all zero" in str(_error(read_vignette, tmp_path / "zero.png"))
    (tmp_path / "broken.png").write_bytes(b"\x89PNG not really")
    assert "decoded" in str(_error(read_vignette, tmp_path / "broken.png"))
    assert "not found" in str(_error(read_vignette, tmp_path / "none.png"))
    for bad in (np.zeros((4, 4)), -vig, np.ones(5), np.full((2, 2), np.nan)):
        with pytest.raises(ShapeError):
            write_vignette(tmp_path / "bad.png", bad)


# ----- image size check -------------------------------------------------------------------------


def test_check_image_size() -> None:
    check_image_size(EUROC_CAM, (480, 752), "cam0/sensor.yaml", "cam0/data/1.png")
    check_image_size(EUROC_CAM, (480, 752, 3), "cam0/sensor.yaml", "cam0/data/1.png")
    with pytest.raises(CalibrationError) as info:
        check_image_size(EUROC_CAM, (1080, 1920), "cam0/sensor.yaml", "cam0/data/1.png")
    msg = str(info.value)
    assert msg.startswith("cam0/sensor.yaml: ") and "752x480" in msg and "1920x1080" in msg
    assert "cam0/data/1.png" in msg and "\n" not in msg
    with pytest.raises(ShapeError):
        check_image_size(EUROC_CAM, (480,), "a", "b")
