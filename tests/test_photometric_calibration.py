"""Photometric model (apply, read/write DSO files) and its estimation from tracked points."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import amrvio.sim.image_formation as sim_if
import amrvio.sim.render as sim_render
import amrvio.sim.scene as sim_scene
from amrvio.errors import ShapeError
from amrvio.photometric.calibrate import (
    CalibrationStatus,
    PhotometricObservations,
    estimate_photometric_calibration,
    fit_response_to_inverse_lut,
    track_observations,
)
from amrvio.photometric.model import MonotoneResponse, PhotometricCalibration, RadialVignette
from amrvio.types.camera import PinholeCamera
from amrvio.types.lie import SE3, SO3


def _rms_inverse(lut: np.ndarray, true_lut: np.ndarray) -> float:
    """RMS difference of two inverse responses, each normalised to 1 at DN 250, over DN 6..249."""
    s = np.arange(6, 250)
    return float(np.sqrt(np.mean((lut[s] / lut[250] - true_lut[s] / true_lut[250]) ** 2)))


def _rms_vignette(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((a / a.max() - b / b.max()) ** 2)))


def test_response_inverse_lut_inverts_curve() -> None:
    resp = MonotoneResponse((0.0, 0.3, 0.55, 0.8, 1.0), gamma=0.7)
    lut = resp.inverse_lut()
    assert lut[0] == 0.0 and lut[255] == pytest.approx(1.0)
    assert np.all(np.diff(lut) > 0)
    assert np.allclose(255 * resp.curve(lut), np.arange(256), atol=0.05)
    with pytest.raises(ShapeError):
        MonotoneResponse((0.0, 0.5, 0.4, 1.0))


def test_correct_applies_inverse_response_vignette_and_exposure(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    lut = np.cumsum(rng.uniform(0.5, 2.0, 256))
    lut -= lut[0]
    vig = RadialVignette(-0.3, 0.05).map(30, 40)
    cal = PhotometricCalibration(lut, vig)
    img = rng.integers(0, 256, (30, 40)).astype(np.uint8)
    out = cal.correct(img, exposure_s=0.01)
    assert out.dtype == np.float32
    assert np.allclose(out, lut[img] / (vig / vig.max()) / 0.01, rtol=1e-5)
    cal.save(tmp_path / "pcalib.txt", tmp_path / "vignette.png")
    back = PhotometricCalibration.load(tmp_path / "pcalib.txt", tmp_path / "vignette.png")
    assert np.allclose(back.inverse_response, lut, rtol=1e-6, atol=1e-6)
    assert back.vignette is not None and cal.vignette is not None
    assert np.allclose(back.vignette, cal.vignette, atol=2e-5)
    with pytest.raises(ShapeError):
        cal.correct(np.zeros((10, 10), np.uint8))
    with pytest.raises(ShapeError):
        PhotometricCalibration(np.zeros(10))


def _synthetic_obs(rng: np.random.Generator, t: np.ndarray, G, V: RadialVignette,
                   W: int = 752, H: int = 480, P: int = 300) -> PhotometricObservations:
    L = rng.uniform(0.02, 1.0, P) * 80
    fr, pt, uv, I = [], [], [], []
    for i in range(t.size):
        j = np.flatnonzero(rng.random(P) < 0.5)
        x = np.stack([rng.uniform(0, W - 1, j.size), rng.uniform(0, H - 1, j.size)], 1)
        E = t[i] * V.at_radius(RadialVignette.radius(x, W, H)) * L[j]
        I.append(np.round(255 * G(E) + rng.normal(0, 0.5, j.size)))
        fr.append(np.full(j.size, i))
        pt.append(j)
        uv.append(x)
    return PhotometricObservations(np.concatenate(fr), np.concatenate(pt), np.concatenate(uv),
                                   np.concatenate(I).astype(float), W, H, t.size)


def test_estimate_recovers_gamma_response_and_vignette_from_exact_observations() -> None:
    rng = np.random.default_rng(0)
    t = 0.004 * 2 ** rng.uniform(-1.5, 1.5, 15)
    V = RadialVignette(-0.35, 0.1, -0.05)
    obs = _synthetic_obs(rng, t, lambda x: np.clip(x, 0, 1) ** (1 / 1.8), V, P=200)
    est = estimate_photometric_calibration(obs, t)
    assert est.status is CalibrationStatus.OK and est.rms_dn < 1.0
    true_lut = (np.arange(256) / 255.0) ** 1.8
    assert _rms_inverse(est.response.inverse_lut(), true_lut) < 0.005
    assert _rms_vignette(est.vignette.map(48, 75), V.map(48, 75)) < 0.005
    # unknown exposures: recovered up to one scale and the response-exponent gauge
    # (log t_est = k log t_true + c), see the module docstring
    est_u = estimate_photometric_calibration(obs, None)
    k, c = np.polyfit(np.log(t), np.log(est_u.exposures_s), 1)
    resid = np.log(est_u.exposures_s) - (k * np.log(t) + c)
    assert np.abs(resid).max() < 0.02 and 0.3 < k < 1.5


def test_too_few_observations_is_a_typed_result() -> None:
    obs = PhotometricObservations(np.zeros(5, np.int64), np.arange(5), np.zeros((5, 2)),
                                  np.full(5, 100.0), 10, 10, 1)
    assert estimate_photometric_calibration(obs).status is CalibrationStatus.TOO_FEW_OBSERVATIONS


def test_calibration_from_simulated_frames_meets_accuracy() -> None:
    W, H = 376, 240
    cam = PinholeCamera(W, H, 0.61 * W, 0.61 * W, (W - 1) / 2, (H - 1) / 2)
    renderer = sim_render.SceneRenderer(sim_scene.make_scene("room", 0), cam)
    R_fwd = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    sensor = sim_if.SensorModel(response=sim_if.CameraResponse(2.2),
                                vignette=RadialVignette(-0.3, 0.05, 0.0), noise=True)
    rng = np.random.default_rng(0)
    images, exposures = [], []
    n = 40
    for k in range(n):  # panning camera: points cross the image; exposure varies 2^+-1.2
        yaw = 0.6 * np.sin(2 * np.pi * k / n) + 0.3 * k / n
        pitch = 0.15 * np.sin(4 * np.pi * k / n)
        R = SO3.exp(np.array([0.0, 0.0, yaw])) @ SO3.exp(np.array([0.0, pitch, 0.0]))
        T = SE3(R, np.array([-1.4, -1.4, 1.0])) @ SE3(SO3.from_matrix(R_fwd), np.zeros(3))
        t = 0.01 * 2 ** (1.2 * np.sin(k * 1.3))
        images.append(sim_if.expose(renderer.irradiance(T), t, sensor, rng))
        exposures.append(t)
    obs = track_observations(images, max_points=250)
    est = estimate_photometric_calibration(obs, np.array(exposures))
    assert est.status is CalibrationStatus.OK
    resp_rms = _rms_inverse(est.response.inverse_lut(), sensor.response.inverse_lut())
    vig_rms = _rms_vignette(est.vignette.map(H, W), sensor.vignette.map(H, W).astype(np.float64))
    assert resp_rms < 0.02, resp_rms
    assert vig_rms < 0.03, vig_rms


def test_fit_response_to_lut_of_a_gamma_curve() -> None:
    lut = 255.0 * (np.arange(256) / 255.0) ** 2.2
    resp, rms = fit_response_to_inverse_lut(lut)
    assert rms < 0.003
    assert _rms_inverse(resp.inverse_lut(), lut) < 0.003


def test_calibration_from_a_sequence_written_by_the_simulator(tmp_path: Path) -> None:
    """`simulate` with scripted EV steps (gamma 2.2 response, v1 = -0.3 vignette, handheld motion
    with blur and sensor noise) -> read back -> track -> estimate with the recorded exposures.
    Truth: the simulator's own pcalib.txt and vignette.png."""
    from amrvio.io.dataset import open_dataset
    from amrvio.photometric.model import compare_inverse_responses
    from amrvio.sim.simulate import SimConfig, simulate

    steps = "0.4:+1,0.8:-1.5,1.2:+1,1.6:-0.8,2.0:+1.2,2.4:-1,2.8:+0.6,3.2:-1.1,3.6:+1"
    simulate(SimConfig(scene="room", motion="handheld", seconds=4.0, fps=10.0, width=376,
                       height=240, ev_steps=steps, exposure_ms=8.0, response_gamma=2.2,
                       vignette_v1=-0.3), tmp_path)
    ds = open_dataset(tmp_path)
    assert ds.inverse_response is not None and ds.vignette is not None
    images = [f.load() for f in ds.frames]
    exposures = np.array([f.exposure_s for f in ds.frames], dtype=np.float64)
    assert np.ptp(np.log2(exposures)) > 1.4  # the steps span more than 1.4 EV
    est = estimate_photometric_calibration(track_observations(images, max_points=250), exposures)
    assert est.status is CalibrationStatus.OK
    cmp = compare_inverse_responses(est.response.inverse_lut(), ds.inverse_response)
    assert cmp.rms_scale_aligned < 0.02, cmp
    assert cmp.rms_at_250 < 0.05, cmp  # carries the extrapolation to DN 250 (rarely unsaturated)
    H, W = images[0].shape
    assert _rms_vignette(est.vignette.map(H, W), ds.vignette) < 0.03


def test_compare_inverse_responses_closed_forms() -> None:
    from amrvio.photometric.model import compare_inverse_responses

    ref = 255.0 * (np.arange(256) / 255.0) ** 2.2
    same = compare_inverse_responses(3.0 * ref + 7.0, ref)  # scale and offset are gauge
    assert same.rms_at_250 < 1e-12 and same.rms_scale_aligned < 1e-12
    lin = compare_inverse_responses(np.arange(256.0), ref)
    assert lin.rms_scale_aligned < lin.rms_at_250
    with pytest.raises(ShapeError):
        compare_inverse_responses(np.zeros(10), ref)
