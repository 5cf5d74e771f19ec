"""Image formation: response, vignette, exposure linearity, noise, motion-blur smear, determinism."""

from __future__ import annotations

import math

import numpy as np
import pytest

from amrvio.errors import ShapeError
from amrvio.photometric.model import RadialVignette
from amrvio.sim import textures as tx
from amrvio.sim.image_formation import (
    CameraResponse,
    SensorModel,
    expose,
    render_frame,
)
from amrvio.sim.render import SceneRenderer
from amrvio.sim.scene import Quad, Scene, make_scene
from amrvio.types.camera import PinholeCamera
from amrvio.types.lie import SE3, SO3

CAM = PinholeCamera(752, 480, 458.654, 457.296, 375.5, 239.5)


@pytest.mark.parametrize("gamma", [1.0, 1.8, 2.2, 0.7])
def test_response_monotone_and_lut_inverse(gamma):
    r = CameraResponse(gamma)
    x = np.linspace(0.0, 1.0, 10001)
    g = r.curve(x)
    assert g[0] == 0.0 and g[-1] == pytest.approx(1.0, abs=1e-12)
    assert np.all(np.diff(g) > 0)
    lut = r.inverse_lut()
    assert lut.shape == (256,) and lut[0] == 0.0 and lut[-1] == pytest.approx(255.0)
    assert np.all(np.diff(lut) > 0)
    # G(G^-1(i)) == i: the LUT is the inverse of the curve (pcalib convention, 0..255 scale).
    assert np.allclose(255.0 * r.curve(lut / 255.0), np.arange(256), atol=1e-6)
    # C1 at the toe: left and right slopes agree.
    h = 1e-7
    left = (r.curve(r.toe) - r.curve(r.toe - h)) / h
    right = (r.curve(r.toe + h) - r.curve(r.toe)) / h
    assert left == pytest.approx(right, rel=1e-4)


def test_response_rejects_bad_parameters():
    with pytest.raises(ShapeError):
        CameraResponse(0.0)
    with pytest.raises(ShapeError):
        CameraResponse(2.2, toe=0.7)


def test_vignette_map_properties():
    v = RadialVignette(-0.3, 0.05, -0.02)
    m = v.map(481, 753)  # odd size: an exact centre pixel
    assert m.shape == (481, 753)
    assert m[240, 376] == pytest.approx(1.0) and m.max() == pytest.approx(1.0)
    assert m[0, 0] == pytest.approx(1.0 - 0.3 + 0.05 - 0.02, rel=1e-6)
    assert np.allclose(m, m[::-1, ::-1]) and np.allclose(m, m[:, ::-1])
    row = m[240, 376:]
    assert np.all(np.diff(row) <= 0)
    with pytest.raises(ShapeError):
        SensorModel(vignette=RadialVignette(-1.2))  # goes negative
    with pytest.raises(ShapeError):
        SensorModel(vignette=RadialVignette(0.3))  # brighter at the corners
    assert SensorModel().vignette == RadialVignette(-0.25)  # the simulator's default fall-off


def _irradiance(h=120, w=160, seed=0):
    tex = tx.procedural_noise(256, seed)
    return np.ascontiguousarray(tex[:h, :w]) * 60.0  # radiance; at 10 ms: energy 0.03..0.51


def test_doubling_exposure_equals_response_of_doubled_irradiance():
    sensor = SensorModel(1.3, CameraResponse(2.2), RadialVignette(-0.3, 0.02), noise=False)
    E = _irradiance()
    t = 0.008
    img1 = expose(E, t, sensor, None)
    img2 = expose(E, 2 * t, sensor, None)
    V = sensor.vignette.map(*E.shape).astype(np.float64)
    energy2 = np.clip(sensor.gain * 2 * t * V * E.astype(np.float64), 0.0, 1.0)
    ref2 = np.rint(255.0 * sensor.response.curve(energy2))
    unsat = ref2 < 255
    assert unsat.mean() > 0.9
    assert np.max(np.abs(img2.astype(int) - ref2)[unsat]) <= 1
    assert np.array_equal(img2, expose(2.0 * E, t, sensor, None))
    # Through the inverse response (pcalib LUT): G^-1(I2) = 2 G^-1(I1) within quantisation.
    r = sensor.response
    lo1 = r.inverse(np.maximum(img1 - 0.5, 0) / 255.0)
    hi1 = r.inverse(np.minimum(img1 + 0.5, 255) / 255.0)
    lo2 = r.inverse(np.maximum(img2 - 0.5, 0) / 255.0)
    hi2 = r.inverse(np.minimum(img2 + 0.5, 255) / 255.0)
    ok = (2 * lo1 <= hi2 + 1e-12) & (lo2 <= 2 * hi1 + 1e-12)
    assert np.all(ok[unsat])


def test_noise_statistics_and_saturation():
    fw, rn, gain = 5000.0, 2.0, 2.0
    sensor = SensorModel(gain, CameraResponse(1.0), RadialVignette(0.0), fw, rn, noise=True)
    x = 0.2  # energy fraction of the well
    E = np.full((400, 400), x / 0.01, np.float32)
    img = expose(E, 0.01, sensor, np.random.default_rng(0)).astype(np.float64)
    mean_ref = 255.0 * gain * x
    sigma_ref = 255.0 * math.sqrt(gain**2 * x / fw + (rn / 255.0) ** 2)  # shot + read noise
    assert img.mean() == pytest.approx(mean_ref, rel=0.01)
    assert img.std() == pytest.approx(math.sqrt(sigma_ref**2 + 1.0 / 12.0), rel=0.05)
    bright = expose(np.full((10, 10), 1e4, np.float32), 0.01, sensor, np.random.default_rng(1))
    assert np.all(bright == 255)
    dark = expose(np.zeros((10, 10), np.float32), 0.01, SensorModel.ideal(), None)
    assert np.all(dark == 0)


def test_expose_rejects_bad_input():
    s = SensorModel.ideal()
    with pytest.raises(ShapeError):
        expose(np.ones((4, 4, 3), np.float32), 0.01, s, None)
    with pytest.raises(ShapeError):
        expose(np.ones((4, 4), np.float32), -0.01, s, None)
    with pytest.raises(ShapeError):
        expose(np.full((4, 4), np.nan, np.float32), 0.01, s, None)
    with pytest.raises(ShapeError):
        expose(np.ones((4, 4), np.float32), 0.01, SensorModel(), None)  # noise needs an rng


def _edge_scene():
    """A wall 3 m ahead (camera-frame z = 3), dark for x < 0 and bright for x > 0."""
    tex = [tx.constant(8, 0.1), tx.constant(8, 0.9)]

    def rect(c0, a, b, tid):
        c0, a, b = (np.asarray(v, dtype=float) for v in (c0, a, b))
        return Quad(np.stack([c0, c0 + a, c0 + a + b, c0 + b]), tid, 100.0, 100.0)

    quads = (rect((-4.0, -3.0, 3.0), (4.0, 0, 0), (0, 6.0, 0), 0),
             rect((0.0, -3.0, 3.0), (4.0, 0, 0), (0, 6.0, 0), 1))
    corners = np.concatenate([q.corners_world for q in quads])
    return Scene("edge", quads, tuple(tex), corners.min(0), corners.max(0))


def _edge_variance(img):
    """Variance (px^2) of the edge's derivative profile across the centre rows."""
    prof = img[200:280].astype(np.float64).mean(axis=0)
    d = np.diff(prof)[300:450]
    d = np.clip(d, 0.0, None)
    x = np.arange(d.size) + 0.5
    m = (d * x).sum() / d.sum()
    return float((d * (x - m) ** 2).sum() / d.sum())


@pytest.mark.parametrize("omega", [3.0, 6.0])
def test_blur_smear_matches_f_omega_T(omega):
    renderer = SceneRenderer(_edge_scene(), CAM)
    T_exp = 0.01
    t0 = 1.0
    t_mid = t0 + T_exp / 2

    def pose_at(t):  # pure rotation about the camera y axis (horizontal image motion)
        return SE3(SO3.exp([0.0, omega * (t - t_mid), 0.0]), np.zeros(3))

    sensor = SensorModel.ideal(1.0)
    sharp = render_frame(renderer, pose_at, t0, T_exp, sensor, None, blur=False)
    blurred = render_frame(renderer, pose_at, t0, T_exp, sensor, None, blur=True)
    L_ref = CAM.fx * omega * T_exp  # seed §5: L = f |w| T
    # Box blur of length L adds L^2 / 12 to the variance of the edge's derivative profile.
    L_meas = math.sqrt(12.0 * (_edge_variance(blurred.image) - _edge_variance(sharp.image)))
    assert L_meas == pytest.approx(L_ref, rel=0.10)
    assert blurred.smear_px_center == pytest.approx(L_ref, rel=0.02)
    assert sharp.n_subframes == 1
    n_min = math.ceil(blurred.smear_px_max / 0.5) + 1
    assert blurred.n_subframes in (n_min, n_min + 1) and blurred.n_subframes % 2 == 1


def test_same_seed_gives_identical_frames():
    scene = make_scene("room", seed=1)
    renderer = SceneRenderer(scene, CAM.scaled(0.25))
    R0 = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])

    def pose_at(t):
        return SE3(SO3(SO3.exp([0.0, 0.0, 0.8 * t]).R @ R0), np.array([-1.5 + 0.5 * t, -1.0, 0.8]))

    sensor = SensorModel(1.5, CameraResponse(2.2), RadialVignette(-0.3))
    frames = [
        render_frame(renderer, pose_at, 0.3, 0.02, sensor, np.random.default_rng(7)).image
        for _ in range(2)
    ]
    other = render_frame(renderer, pose_at, 0.3, 0.02, sensor, np.random.default_rng(8)).image
    assert frames[0].tobytes() == frames[1].tobytes()
    assert frames[0].tobytes() != other.tobytes()


def test_predicted_smear_uses_depth_for_translation():
    """Sideways translation v over T in front of a wall at depth Z: smear = f v T / Z (exact for a
    fronto-parallel plane), and points at infinity would not move."""
    renderer = SceneRenderer(_edge_scene(), CAM)
    v, T_exp, Z = 2.0, 0.01, 3.0

    def pose_at(t):
        return SE3(SO3.identity(), np.array([v * (t - 0.005), 0.0, 0.0]))

    fr = render_frame(renderer, pose_at, 0.0, T_exp, SensorModel.ideal(), None, blur=True)
    ref = CAM.fx * v * T_exp / Z
    assert fr.smear_px_center == pytest.approx(ref, rel=1e-6)
    assert fr.smear_px_max == pytest.approx(ref, rel=1e-6)  # same depth everywhere on the wall
    assert fr.n_subframes == math.ceil(ref / 0.5) + 1 + (1 - (math.ceil(ref / 0.5) + 1) % 2)
