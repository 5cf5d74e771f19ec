"""Camera models against closed forms, finite differences and OpenCV."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from amrvio.errors import ShapeError
from amrvio.types.camera import (
    CameraModel,
    EquidistantCamera,
    FovCamera,
    PinholeCamera,
    RadTanCamera,
    camera_from_params,
)

# EuRoC V1_01 cam0 (strong barrel distortion), a radtan with k3, and a Kalibr-like fisheye.
EUROC = RadTanCamera(
    752, 480, 458.654, 457.296, 367.215, 248.375, -0.28340811, 0.07395907, 0.00019359, 1.76187114e-05
)
RADTAN_K3 = RadTanCamera(640, 480, 520.0, 515.0, 322.0, 241.0, 0.12, -0.21, 0.0011, -0.0007, 0.05)
# TUM-VI-like distortion; focal chosen so that the image corners stay below 90 degrees off-axis
FISHEYE = EquidistantCamera(512, 512, 250.0, 249.0, 254.93, 256.90, 0.0034, 0.0007, -0.0020, 0.0002)
# TUM monoVO-like FOV camera (omega of sequence 01); size chosen so corners have r_d omega < pi/2
FOV = FovCamera(1024, 960, 446.9, 447.1, 511.5, 479.5, 0.933271)
PINHOLE = PinholeCamera(1241, 376, 718.856, 718.856, 607.1928, 185.2157)
CAMERAS: list[CameraModel] = [PINHOLE, EUROC, RADTAN_K3, FISHEYE, FOV]
IDS = ["pinhole", "euroc_radtan", "radtan_k3", "equidistant", "fov"]


def _points_in_view(cam: CameraModel, n: int, seed: int) -> np.ndarray:
    """(n, 3) points in front of the camera whose projections fall inside the image."""
    rng = np.random.default_rng(seed)
    uv = rng.uniform([0.0, 0.0], [cam.width - 1.0, cam.height - 1.0], size=(n, 2))
    rays = cam.unproject(uv)
    depth = rng.uniform(0.3, 30.0, size=n)
    return rays * depth[:, None]


@pytest.mark.parametrize("cam", CAMERAS, ids=IDS)
def test_project_unproject_round_trip(cam: CameraModel) -> None:
    rng = np.random.default_rng(1)
    uv = rng.uniform([0.0, 0.0], [cam.width - 1.0, cam.height - 1.0], size=(5000, 2))
    rays = cam.unproject(uv)
    assert np.all(np.isfinite(rays))
    np.testing.assert_array_equal(rays[:, 2], 1.0)
    np.testing.assert_allclose(cam.project(rays), uv, atol=1e-9, rtol=0)
    # and the other way: points -> pixels -> rays recover x/z, y/z
    pts = _points_in_view(cam, 2000, seed=2)
    back = cam.unproject(cam.project(pts))
    np.testing.assert_allclose(back[:, :2], pts[:, :2] / pts[:, 2:3], atol=1e-12, rtol=1e-9)


@pytest.mark.parametrize("cam", CAMERAS, ids=IDS)
@settings(max_examples=60, deadline=None)
@given(
    u=st.floats(0.0, 1.0),
    v=st.floats(0.0, 1.0),
    depth=st.floats(0.05, 1e3),
)
def test_round_trip_property(cam: CameraModel, u: float, v: float, depth: float) -> None:
    uv = np.array([[u * (cam.width - 1), v * (cam.height - 1)]])
    point = cam.unproject(uv) * depth
    np.testing.assert_allclose(cam.project(point), uv, atol=1e-9, rtol=0)
    np.testing.assert_allclose(cam.undistort_points(uv), cam.pinhole().project(point), atol=1e-9)


@pytest.mark.parametrize("cam", CAMERAS, ids=IDS)
def test_projection_jacobian_matches_central_differences(cam: CameraModel) -> None:
    pts = _points_in_view(cam, 300, seed=3)
    pts = np.vstack([pts, [[0.0, 0.0, 2.0], [1e-9, -1e-9, 1.0]]])  # optical axis: r -> 0 branch
    jac = cam.project_jacobian(pts)
    assert jac.shape == (pts.shape[0], 2, 3)
    num = np.empty_like(jac)
    for k in range(3):
        h = 1e-6 * np.maximum(np.abs(pts[:, 2]), 1.0)
        dp = np.zeros_like(pts)
        dp[:, k] = h
        num[:, :, k] = (cam.project(pts + dp) - cam.project(pts - dp)) / (2.0 * h[:, None])
    scale = np.abs(jac).max(axis=(1, 2), keepdims=True)
    rel = np.abs(jac - num) / scale
    assert rel.max() < 1e-6, rel.max()


@pytest.mark.parametrize("cam", [EUROC, RADTAN_K3], ids=["euroc_radtan", "radtan_k3"])
def test_radtan_matches_opencv(cam: RadTanCamera) -> None:
    pts = _points_in_view(cam, 1000, seed=4)
    expected, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), cam.K, np.array(cam.distortion))
    np.testing.assert_allclose(cam.project(pts), expected[:, 0, :], atol=1e-9, rtol=0)

    rng = np.random.default_rng(5)
    uv = rng.uniform([0.0, 0.0], [cam.width - 1.0, cam.height - 1.0], size=(1000, 2))
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-14)
    ref = cv2.undistortPointsIter(uv[:, None], cam.K, np.array(cam.distortion), None, cam.K, crit)
    np.testing.assert_allclose(cam.undistort_points(uv), ref[:, 0, :], atol=1e-8, rtol=0)


def test_equidistant_matches_opencv_fisheye() -> None:
    cam = FISHEYE
    pts = _points_in_view(cam, 1000, seed=6)
    d = np.array(cam.distortion)
    expected, _ = cv2.fisheye.projectPoints(pts[:, None, :], np.zeros(3), np.zeros(3), cam.K, d)
    np.testing.assert_allclose(cam.project(pts), expected[:, 0, :], atol=1e-9, rtol=0)

    rng = np.random.default_rng(7)
    uv = rng.uniform([0.0, 0.0], [cam.width - 1.0, cam.height - 1.0], size=(1000, 2))
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-14)
    ref = cv2.fisheye.undistortPoints(uv[:, None, :], cam.K, d, P=cam.K, criteria=crit)
    np.testing.assert_allclose(cam.undistort_points(uv), ref[:, 0, :], atol=1e-8, rtol=0)


def test_fov_closed_form() -> None:
    # Devernay & Faugeras 2001: r_d = atan(2 r tan(w/2)) / w, written out for one point
    w = 0.933271
    x, y = 0.3, -0.4
    r = 0.5
    rd = np.arctan(2.0 * r * np.tan(w / 2.0)) / w
    expected = [446.9 * x * rd / r + 511.5, 447.1 * y * rd / r + 479.5]
    np.testing.assert_allclose(FOV.project(np.array([[2 * x, 2 * y, 2.0]])), [expected], atol=1e-10)
    # omega = 0 is the pinhole; r_d omega >= pi/2 cannot be inverted
    flat = FovCamera(100, 100, 50.0, 50.0, 49.5, 49.5, 0.0)
    np.testing.assert_allclose(flat.project(np.array([[1.0, 2.0, 4.0]])), [[62.0, 74.5]])
    far = FOV.unproject(np.array([[511.5 + 446.9 * (np.pi / 2 / w + 0.01), 479.5]]))
    assert np.all(np.isnan(far))
    with pytest.raises(ShapeError):
        FovCamera(100, 100, 50.0, 50.0, 49.5, 49.5, -0.1)


def test_pinhole_closed_form() -> None:
    pts = np.array([[1.0, -2.0, 4.0], [0.0, 0.0, 1.0]])
    expected = np.array(
        [[718.856 * 0.25 + 607.1928, -718.856 * 0.5 + 185.2157], [607.1928, 185.2157]]
    )
    np.testing.assert_allclose(PINHOLE.project(pts), expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose(PINHOLE.undistort_points(expected), expected, atol=1e-12)


@pytest.mark.parametrize("cam", [EUROC, FISHEYE], ids=["euroc_radtan", "equidistant"])
def test_undistort_image_moves_blobs_to_pinhole_positions(cam: CameraModel) -> None:
    # Render Gaussian blobs defined in the ideal pinhole image, seen through the distortion:
    # I_dist(u) = sum_i G(undistort(u) - p_i). Undistorting the image must put them back at p_i.
    sigma = 2.0
    rng = np.random.default_rng(8)
    margin = 40.0
    targets = rng.uniform([margin, margin], [cam.width - margin, cam.height - margin], size=(25, 2))
    us, vs = np.meshgrid(np.arange(cam.width, dtype=float), np.arange(cam.height, dtype=float))
    grid = np.stack([us.ravel(), vs.ravel()], axis=1)
    ideal = cam.undistort_points(grid)
    img = np.zeros(grid.shape[0])
    for p in targets:
        d2 = np.sum((ideal - p) ** 2, axis=1)
        img += np.exp(-0.5 * np.nan_to_num(d2, nan=1e9) / sigma**2)
    distorted = (img.reshape(cam.height, cam.width) * 200.0).astype(np.float32)

    out = cam.undistort_image(distorted)
    assert out.shape == distorted.shape and out.dtype == distorted.dtype
    worst = 0.0
    for p in targets:
        u0, v0 = int(round(p[0])), int(round(p[1]))
        win = out[v0 - 6 : v0 + 7, u0 - 6 : u0 + 7].astype(float)
        wu, wv = np.meshgrid(np.arange(u0 - 6, u0 + 7), np.arange(v0 - 6, v0 + 7))
        centroid = np.array([np.sum(win * wu), np.sum(win * wv)]) / np.sum(win)
        worst = max(worst, float(np.linalg.norm(centroid - p)))
    assert worst < 0.3
    # the blob did move: in the distorted image it sat at project(p) which differs from p
    assert np.abs(cam.distort_points(targets) - targets).max() > 3.0


def test_undistort_image_keeps_type_and_channels() -> None:
    img = np.full((EUROC.height, EUROC.width, 3), 100, dtype=np.uint8)
    out = EUROC.undistort_image(img)
    assert out.shape == img.shape and out.dtype == np.uint8
    assert out[EUROC.height // 2, EUROC.width // 2, 0] == 100
    grey = EUROC.undistort_image(img[:, :, 0])
    assert grey.shape == (EUROC.height, EUROC.width)
    with pytest.raises(ShapeError):
        EUROC.undistort_image(np.zeros((10, 10), np.uint8))


def test_behind_camera_gives_nan_rows() -> None:
    pts = np.array([[0.1, 0.2, 1.0], [0.1, 0.2, 0.0], [0.1, 0.2, -1.0]])
    for cam in CAMERAS:
        uv = cam.project(pts)
        assert np.all(np.isfinite(uv[0])) and np.all(np.isnan(uv[1:]))
        jac = cam.project_jacobian(pts)
        assert np.all(np.isfinite(jac[0])) and np.all(np.isnan(jac[1:]))


def test_unproject_outside_invertible_region_is_nan() -> None:
    # r_d = r - 0.4 r^3 peaks at r_d = 0.609 (fold at r = 0.913): beyond that no inverse exists
    cam = RadTanCamera(100, 100, 100.0, 100.0, 50.0, 50.0, -0.4, 0.0, 0.0, 0.0)
    rays = cam.unproject(np.array([[50.0 + 70.0, 50.0], [50.0 + 30.0, 50.0]]))
    assert np.all(np.isnan(rays[0])) and np.all(np.isfinite(rays[1]))
    # equidistant without distortion: theta_d = theta < pi/2
    eq = EquidistantCamera(100, 100, 10.0, 10.0, 50.0, 50.0, 0.0, 0.0, 0.0, 0.0)
    rays = eq.unproject(np.array([[50.0 + 16.0, 50.0], [50.0 + 15.0, 50.0]]))
    assert np.all(np.isnan(rays[0]))
    np.testing.assert_allclose(rays[1], [np.tan(1.5), 0.0, 1.0], rtol=1e-12)


@pytest.mark.parametrize("cam", CAMERAS, ids=IDS)
def test_bad_shapes_and_nan_raise(cam: CameraModel) -> None:
    for bad in (np.zeros(3), np.zeros((4, 2)), np.zeros((2, 3, 1)), np.array([[0.0, np.nan, 1.0]])):
        with pytest.raises(ShapeError):
            cam.project(bad)
        with pytest.raises(ShapeError):
            cam.project_jacobian(bad)
    for bad in (np.zeros(2), np.zeros((4, 3)), np.array([[np.inf, 1.0]])):
        with pytest.raises(ShapeError):
            cam.unproject(bad)
        with pytest.raises(ShapeError):
            cam.undistort_points(bad)
    assert cam.project(np.zeros((0, 3))).shape == (0, 2)
    assert cam.unproject(np.zeros((0, 2))).shape == (0, 3)


def test_bad_parameters_raise() -> None:
    with pytest.raises(ShapeError):
        PinholeCamera(0, 480, 500.0, 500.0, 320.0, 240.0)
    with pytest.raises(ShapeError):
        PinholeCamera(640, 480, -500.0, 500.0, 320.0, 240.0)
    with pytest.raises(ShapeError):
        PinholeCamera(640, 480, 500.0, 500.0, float("nan"), 240.0)
    with pytest.raises(ShapeError):
        PinholeCamera(640.5, 480, 500.0, 500.0, 320.0, 240.0)  # type: ignore[arg-type]
    with pytest.raises(ShapeError):
        RadTanCamera(640, 480, 500.0, 500.0, 320.0, 240.0, 0.1, float("inf"), 0.0, 0.0)
    with pytest.raises(ShapeError):
        EquidistantCamera(640, 480, 500.0, 500.0, 320.0, 240.0, 0.1, 0.0, float("nan"), 0.0)
    with pytest.raises(ShapeError):
        EUROC.scaled(0.0)
    with pytest.raises(ShapeError):
        PinholeCamera(640, 480, "fast", 500.0, 320.0, 240.0)  # type: ignore[arg-type]
    with pytest.raises(ShapeError):
        RadTanCamera(640, 480, 500.0, 500.0, 320.0, 240.0, None, 0.0, 0.0, 0.0)  # type: ignore[arg-type]


@pytest.mark.parametrize("cam", CAMERAS, ids=IDS)
def test_scaled_and_pinhole(cam: CameraModel) -> None:
    half = cam.scaled(0.5)
    assert type(half) is type(cam) and half.distortion == cam.distortion
    assert (half.width, half.height) == (round(cam.width / 2), round(cam.height / 2))
    pts = _points_in_view(cam, 50, seed=9)
    # pixel centres: u' = f (u + 0.5) - 0.5
    np.testing.assert_allclose(half.project(pts), 0.5 * (cam.project(pts) + 0.5) - 0.5, atol=1e-9)
    ph = cam.pinhole()
    assert isinstance(ph, PinholeCamera) and ph.distortion == ()
    np.testing.assert_array_equal(ph.K, cam.K)
    assert cam.scaled(1.0) == cam


def test_properties_and_hashing() -> None:
    assert EUROC.distortion_model == "radtan"
    assert FISHEYE.distortion_model == "equidistant"
    assert PINHOLE.distortion_model == "none"
    assert FOV.distortion_model == "fov" and FOV.distortion == (0.933271,)
    assert EUROC.distortion == (-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05, 0.0)
    assert FISHEYE.distortion == (0.0034, 0.0007, -0.0020, 0.0002)
    np.testing.assert_array_equal(
        EUROC.K, [[458.654, 0, 367.215], [0, 457.296, 248.375], [0, 0, 1]]
    )
    assert EUROC.resolution == (752, 480)
    same = RadTanCamera(752, 480, 458.654, 457.296, 367.215, 248.375, *EUROC.distortion)
    assert same == EUROC and hash(same) == hash(EUROC)
    assert EUROC.in_image(np.array([[0.0, 0.0], [751.0, 479.0], [-1.0, 3.0]])).tolist() == [
        True,
        True,
        False,
    ]


def test_camera_from_params() -> None:
    intr = [458.654, 457.296, 367.215, 248.375]
    cam = camera_from_params("pinhole", "radtan", intr, EUROC.distortion[:4], [752, 480])
    assert cam == EUROC
    assert camera_from_params("pinhole", "radial-tangential", intr, EUROC.distortion[:4], [752, 480])
    fish = camera_from_params(
        "Pinhole", "equidistant", [250.0, 249.0, 254.93, 256.90], FISHEYE.distortion, (512, 512)
    )
    assert fish == FISHEYE
    ph = camera_from_params("pinhole", "none", intr, [], [752, 480])
    assert ph == EUROC.pinhole()
    with pytest.raises(ValueError, match="omni"):
        camera_from_params("omni", "radtan", intr, [0, 0, 0, 0], [752, 480])
    assert camera_from_params("pinhole", "fov", intr, [0.9], [752, 480]) == FovCamera(
        752, 480, 458.654, 457.296, 367.215, 248.375, 0.9
    )
    with pytest.raises(ValueError, match="double_sphere"):
        camera_from_params("pinhole", "double_sphere", intr, [0.9, 0.5], [752, 480])
    with pytest.raises(ShapeError):
        camera_from_params("pinhole", "fov", intr, [0.9, 0.1], [752, 480])
    with pytest.raises(ShapeError):
        camera_from_params("pinhole", "radtan", intr, [0.1, 0.2, 0.3], [752, 480])
    with pytest.raises(ShapeError):
        camera_from_params("pinhole", "equidistant", intr, [0.1, 0.2, 0.3, 0.4, 0.5], [752, 480])
    with pytest.raises(ShapeError):
        camera_from_params("pinhole", "radtan", intr[:3], [0, 0, 0, 0], [752, 480])
    with pytest.raises(ShapeError):
        camera_from_params("pinhole", "radtan", intr, [0, 0, 0, 0], [752])
    with pytest.raises(ShapeError):
        camera_from_params("pinhole", "radtan", intr, [0, 0, 0, 0], [752.5, 480])
