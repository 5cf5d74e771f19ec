"""Blur score, affine brightness fit, exposure change, smear, parallax and excitation."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from amrvio.diagnostics.blur import BlurScorer, var_laplacian
from amrvio.diagnostics.excitation import ExcitationConfig, ExcitationStatus, compute_excitation
from amrvio.diagnostics.exposure import estimate_exposure_change, fit_exposure_same_pixel
from amrvio.diagnostics.parallax import RotationSource, rotation_compensated_parallax
from amrvio.diagnostics.smear import (
    integrate_gyro,
    max_exposure_for_smear,
    predict_smear,
    smear_field,
)
from amrvio.errors import ShapeError
from amrvio.photometric.affine import (
    AffineStatus,
    fit_affine_closed_form,
    fit_affine_robust,
)
from amrvio.types.camera import PinholeCamera, RadTanCamera
from amrvio.types.lie import so3_exp
from amrvio.types.sensors import ImuData


def _texture(seed: int = 0, shape: tuple[int, int] = (240, 320)) -> np.ndarray:
    rng = np.random.default_rng(seed)
    base = np.zeros(shape, np.float32)
    for s in (2, 4, 8, 16, 32):
        n = rng.normal(size=(shape[0] // s + 2, shape[1] // s + 2)).astype(np.float32)
        base += cv2.resize(n, (shape[1], shape[0]), interpolation=cv2.INTER_CUBIC)[: shape[0], : shape[1]]
    base = (base - base.min()) / (base.max() - base.min())
    return np.asarray(np.clip(20 + 200 * base, 0, 255), np.uint8)


# ---- blur ------------------------------------------------------------------------------------

def test_var_laplacian_matches_numpy_and_falls_with_blur() -> None:
    img = _texture()
    f = img.astype(np.float64)
    lap = f[:-2, 1:-1] + f[2:, 1:-1] + f[1:-1, :-2] + f[1:-1, 2:] - 4 * f[1:-1, 1:-1]
    # cv2 reflects at the border: compare on the interior-dominated value to 2 %
    assert var_laplacian(img) == pytest.approx(lap.var(), rel=0.02)
    scores = [var_laplacian(cv2.blur(img, (k, 1))) for k in (1, 3, 5, 9, 15)]
    assert all(a > b for a, b in zip(scores, scores[1:], strict=False))
    assert var_laplacian(img, step=2) == pytest.approx(var_laplacian(img), rel=0.1)
    # uint8 (int16 Laplacian) and float input give the same value, also at full contrast
    edges = np.where(np.indices((40, 40)).sum(axis=0) % 2 == 0, 255, 0).astype(np.uint8)
    for u8 in (img, edges):
        for step in (1, 2):
            assert var_laplacian(u8, step) == pytest.approx(
                var_laplacian(u8.astype(np.float32), step), rel=1e-6)


def test_var_laplacian_bad_input() -> None:
    with pytest.raises(ShapeError):
        var_laplacian(np.zeros((2, 5)))
    with pytest.raises(ShapeError):
        var_laplacian(np.full((10, 10), np.nan))
    assert var_laplacian(np.full((20, 20), 7, np.uint8)) == 0.0


def test_blur_scorer_normalises_across_scenes() -> None:
    scorer = BlurScorer()
    for s in [100.0, 104.0, 98.0, 101.0]:
        assert not scorer.update(s).is_blurred
    r = scorer.update(30.0)
    assert r.is_blurred and r.ratio == pytest.approx(30.0 / 100.5, rel=1e-6)
    # a scene 10x less textured: the same relative blur gives the same ratio once re-referenced
    scorer2 = BlurScorer()
    for s in [10.0, 10.4, 9.8, 10.1]:
        scorer2.update(s)
    assert scorer2.update(3.0).ratio == pytest.approx(r.ratio, rel=1e-6)
    with pytest.raises(ShapeError):
        scorer.update(float("nan"))


# ---- affine fit -------------------------------------------------------------------------------

def test_affine_closed_form_exact_and_matches_lstsq() -> None:
    rng = np.random.default_rng(1)
    x = rng.uniform(0, 200, 1000)
    y = 1.3 * x - 7.0 + rng.normal(0, 2, x.size)
    fit = fit_affine_closed_form(x, y)
    A = np.stack([x, np.ones_like(x)], 1)
    ref = np.linalg.lstsq(A, y, rcond=None)[0]
    assert fit.a == pytest.approx(ref[0], rel=1e-10) and fit.b == pytest.approx(ref[1], abs=1e-8)
    assert fit_affine_closed_form(np.ones(10), np.ones(10)).status is AffineStatus.NO_CONTRAST
    assert fit_affine_closed_form(np.ones(1), np.ones(1)).status is AffineStatus.TOO_FEW_SAMPLES
    with pytest.raises(ShapeError):
        fit_affine_closed_form(np.ones(3), np.ones(4))


def test_affine_robust_with_saturation_and_outliers() -> None:
    img = _texture(2)
    a, b = 1.6, 12.0
    cur = np.clip(np.round(a * img.astype(np.float64) + b), 0, 255).astype(np.uint8)
    assert (cur >= 250).mean() > 0.05
    rng = np.random.default_rng(3)
    idx = rng.choice(cur.size, cur.size // 20, replace=False)
    cur.ravel()[idx] = rng.integers(0, 255, idx.size)  # 5 % gross outliers
    closed = fit_affine_closed_form(img, cur)
    robust = fit_affine_robust(img, cur)
    assert abs(closed.a - a) > 0.05  # plain least squares is pulled by clipping and outliers
    assert robust.a == pytest.approx(a, rel=0.005) and robust.b == pytest.approx(b, abs=0.3)
    assert robust.ev == pytest.approx(np.log2(robust.a))


def test_linearise_recovers_true_exposure_ratio() -> None:
    gamma = 2.2
    lut = (np.arange(256) / 255.0) ** gamma  # G^-1 of a gamma response
    img = _texture(4)
    energy = (img / 255.0) ** gamma
    cur = np.clip(np.round(255 * np.clip(energy * 2 ** -0.6, 0, 1) ** (1 / gamma)), 0, 255)
    raw = fit_affine_robust(img, cur)
    lin = fit_exposure_same_pixel(img, cur.astype(np.uint8), inverse_response=lut)
    assert abs(raw.ev + 0.6) > 0.2  # compressed by the response
    assert lin.ev == pytest.approx(-0.6, abs=0.03)
    assert lin.flag


def test_exposure_change_klt_under_motion() -> None:
    img = _texture(5, (300, 400))
    M = np.array([[1, 0, 4.0], [0, 1, -3.0]], dtype=np.float32)
    moved = cv2.warpAffine(img, M, (400, 300), borderMode=cv2.BORDER_REFLECT)
    cur = np.clip(np.round(0.8 * moved.astype(np.float64)), 0, 255).astype(np.uint8)
    ch = estimate_exposure_change(img, cur)
    assert ch.method == "klt" and ch.n_tracks >= 30 and ch.valid
    assert ch.a == pytest.approx(0.8, rel=0.03)
    assert ch.ev == pytest.approx(np.log2(0.8), abs=0.05)
    same = fit_exposure_same_pixel(img, cur)
    assert abs(same.a - 0.8) > abs(ch.a - 0.8)  # the same pixel is wrong under motion
    # with an offset (a black level: y - o = k (x - o)), EV is log2(a), the offset fitted apart;
    # ev_median is the brightness ratio at the median intensity
    cur_b = np.clip(np.round(0.8 * moved.astype(np.float64) + 6), 0, 255).astype(np.uint8)
    chb = estimate_exposure_change(img, cur_b)
    m = chb.fit.x_median
    assert chb.ev == pytest.approx(np.log2(0.8), abs=0.03)
    assert chb.b == pytest.approx(6.0, abs=1.5)
    assert chb.ev_median == pytest.approx(np.log2((chb.a * m + chb.b) / m), abs=1e-9)
    assert chb.flag


def test_exposure_change_blur_is_not_an_exposure_step() -> None:
    img = _texture(6, (300, 400))
    M = np.array([[1, 0, 2.5], [0, 1, 1.5]], dtype=np.float32)
    blurred = cv2.blur(cv2.warpAffine(img, M, (400, 300), borderMode=cv2.BORDER_REFLECT), (9, 1))
    ch = estimate_exposure_change(img, blurred)
    assert abs(ch.ev) < 0.1 and not ch.flag


# ---- gyro smear -------------------------------------------------------------------------------

def _cam() -> PinholeCamera:
    return PinholeCamera(752, 480, 460.0, 458.0, 370.0, 245.0)


def test_smear_centre_matches_seed_rule_and_grows_off_axis() -> None:
    cam = _cam()
    t = np.arange(0, 100) * 5_000_000
    g = np.tile([0.0, 2.0, 0.0], (100, 1))  # 2 rad/s about the camera y axis
    p = predict_smear(cam, t, g, 250_000_000, 0.008)
    theta = 2.0 * 0.008
    assert p.center_px == pytest.approx(cam.fx * np.tan(theta), rel=1e-6)  # f |w| T (seed Problem 5)
    assert p.center_px == pytest.approx(460 * 2 * 0.008, rel=0.01)
    # exact at the image border: u = cx + f tan(atan((u0-cx)/f) + theta)
    u0 = 0.0
    ang = np.arctan((u0 - cam.cx) / cam.fx)
    expect = abs(cam.cx + cam.fx * np.tan(ang + theta) - u0)
    assert p.max_px >= expect * 0.999 and p.max_px > p.mean_px > p.center_px * 0.99


def test_integrate_gyro_exact_for_constant_rate_and_extrinsic() -> None:
    t = np.arange(0, 50) * 5_000_000
    w = np.array([0.3, -0.2, 1.1])
    g = np.tile(w, (50, 1))
    R_cb = so3_exp(np.array([0.1, 0.5, -0.3]))
    R = integrate_gyro(t, g, 12_345_678, 140_000_000, R_cam_body=R_cb)
    dt = (140_000_000 - 12_345_678) * 1e-9
    assert np.allclose(R, so3_exp(R_cb @ w * dt), atol=1e-12)
    assert np.allclose(integrate_gyro(t, g * 0 + 1e-9, 0, 10_000_000), so3_exp(np.full(3, 1e-11)))


def test_smear_is_the_path_length_when_the_rotation_turns_back() -> None:
    # +w for the first half of the exposure, -w for the second: the camera ends where it
    # started, but each pixel swept out and back. At the principal point of a pinhole turning
    # about its y axis, u = cx + f tan(theta): the path is 2 f tan(w T / 2); the start-to-end
    # distance would be 0.
    cam = PinholeCamera(376, 240, 230.0, 230.0, 188.0, 120.0)
    w, T, t_mid = 2.0, 0.02, 1_000_000_000
    t = np.arange(t_mid - 20_000_000, t_mid + 20_000_001, 100_000, dtype=np.int64)
    g = np.zeros((t.size, 3))
    g[:, 1] = np.where(t <= t_mid, w, -w)
    p = predict_smear(cam, t, g, t_mid, T)
    assert p.center_px == pytest.approx(2 * cam.fx * np.tan(w * T / 2), rel=0.01)
    assert p.max_px >= p.center_px and p.rotation_max_px == p.max_px
    assert np.linalg.norm(p.omega_cam_rad_s) < 0.02 * w  # the net rotation is ~0


def test_smear_with_distortion_uses_camera_model() -> None:
    cam = RadTanCamera(752, 480, 458.654, 457.296, 367.215, 248.375, -0.2834, 0.0740, 0.0002, 0.0)
    R = so3_exp(np.array([0.0, 0.01, 0.0]))
    uv0, disp = smear_field(cam, R)
    rays = cam.unproject(uv0) @ R
    ref = np.linalg.norm(cam.project(rays) - uv0, axis=1)
    assert np.allclose(disp, ref)
    _, pin = smear_field(cam.pinhole(), R)
    assert not np.allclose(disp, pin, rtol=0.01)


def test_max_exposure_advice_keeps_smear_at_bound() -> None:
    cam = _cam()
    w = np.array([0.0, 3.0, 0.5])
    T = max_exposure_for_smear(cam, w, bound_px=2.0)
    _, d = smear_field(cam, so3_exp(w * T))
    assert np.nanmax(d) == pytest.approx(2.0, rel=1e-3)
    assert max_exposure_for_smear(cam, np.zeros(3)) == 1.0


# ---- parallax -----------------------------------------------------------------------------------

def test_parallax_pure_rotation_is_zero_and_translation_is_not() -> None:
    cam = _cam()
    rng = np.random.default_rng(7)
    P = np.stack([rng.uniform(-3, 3, 200), rng.uniform(-2, 2, 200), rng.uniform(4, 10, 200)], 1)
    u0 = cam.project(P)
    R = so3_exp(np.array([0.01, 0.05, -0.02]))
    u_rot = cam.project(P @ R.T)
    res = rotation_compensated_parallax(cam, u0, u_rot, R)
    assert res.median_px < 1e-9 and res.rotation_source is RotationSource.GYRO
    raw = rotation_compensated_parallax(cam, u0, u_rot, None, use_essential=False)
    assert raw.median_px > 10
    t = np.array([0.5, 0.0, 0.0])
    u_tr = cam.project(P @ R.T + t)
    with_t = rotation_compensated_parallax(cam, u0, u_tr, R)
    pure_t = np.median(np.linalg.norm(cam.project(P + R.T @ t) - u0, axis=1))
    assert with_t.median_px == pytest.approx(pure_t, rel=0.3)
    ess = rotation_compensated_parallax(cam, u0, u_tr, None)
    assert ess.rotation_source is RotationSource.ESSENTIAL
    assert np.allclose(ess.R_cur_kf, R, atol=1e-3)
    assert ess.median_px == pytest.approx(with_t.median_px, rel=0.05)
    with pytest.raises(ShapeError):
        rotation_compensated_parallax(cam, u0, u0[:5])


# ---- excitation ----------------------------------------------------------------------------------

def _imu(acc: np.ndarray, gyro: np.ndarray) -> ImuData:
    n = acc.shape[0]
    return ImuData(np.arange(n, dtype=np.int64) * 5_000_000, gyro, acc)


def test_excitation_constant_velocity_is_degenerate() -> None:
    n = 400
    rng = np.random.default_rng(0)
    acc = np.tile([0.0, 0.0, 9.81], (n, 1)) + rng.normal(0, 0.02, (n, 3))
    ex = compute_excitation(_imu(acc, np.zeros((n, 3))))
    assert ex.degenerate and ex.status is ExcitationStatus.LOW_ACCELERATION
    Rs = np.repeat(np.eye(3)[None], n, 0)
    ex_g = compute_excitation(_imu(acc, np.zeros((n, 3))), R_world_body=Rs)
    assert ex_g.gravity_removed and ex_g.accel_std_m_s2 < 0.1


def test_excitation_forward_stop_turn() -> None:
    n = 400
    t = np.arange(n) * 0.005
    ax = np.where(t < 1.0, 1.0, -1.0)  # accelerate then brake
    ay = np.where(t > 1.0, 0.8, 0.0)
    acc = np.stack([ax, ay, np.full(n, 9.81)], 1)
    gyro = np.stack([np.zeros(n), np.zeros(n), np.where(t > 1.0, 0.5, 0.0)], 1)
    ex = compute_excitation(_imu(acc, gyro), R_world_body=np.repeat(np.eye(3)[None], n, 0))
    assert not ex.degenerate and ex.status is ExcitationStatus.OK
    assert ex.accel_std_m_s2 == pytest.approx(np.sqrt(np.var(ax) + np.var(ay)), rel=1e-2)
    assert np.degrees(ex.accel_dir_change_rad) > 90
    assert abs(ex.gyro_axes[0] @ np.array([0, 0, 1.0])) == pytest.approx(1.0, abs=1e-9)
    assert ex.gyro_max_rad_s == pytest.approx(0.5)
    assert compute_excitation(_imu(acc[:3], gyro[:3])).status is ExcitationStatus.TOO_FEW_SAMPLES
    assert ex.with_condition_number(12.0).condition_number == 12.0


def test_excitation_ignores_vibration() -> None:
    n = 400
    t = np.arange(n) * 0.005
    vib = 2.0 * np.sin(2 * np.pi * 40.0 * t)  # 40 Hz rotor/floor vibration, 2 m/s^2
    acc = np.stack([vib, np.zeros(n), np.full(n, 9.81)], 1)
    ex = compute_excitation(_imu(acc, np.zeros((n, 3))))
    assert ex.degenerate
    raw = compute_excitation(_imu(acc, np.zeros((n, 3))),
                             config=ExcitationConfig(lowpass_s=0.0))
    assert not raw.degenerate
