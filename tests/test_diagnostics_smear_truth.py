"""Total (rotational + translational) smear against the simulator's true image motion.

The simulator's truth (amrvio.sim.image_formation.predict_smear) follows every visible scene
point of a 16 px grid through the camera path over the exposure, with the rendered depth. The
prediction is the diagnostics stage's: gyro rotation plus the translation ``v T`` at the depths
of tracked points (corners of the rendered frame, their true depth and the true velocity, as a
VIO or a VO with scale would pass them). Straight driving in the 2.4 m corridor moves the walls
and the floor by 2-4 px in a 20 ms exposure while the gyro sees nothing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

import amrvio.sim.image_formation as sim_if
from amrvio.diagnostics.frame import FrameDiagnostics
from amrvio.diagnostics.smear import CameraMotion, max_exposure_for_smear, smear_at_pixels
from amrvio.errors import ShapeError
from amrvio.sim.motion import default_T_body_cam, make_motion, parse_blur_bursts
from amrvio.sim.render import SceneRenderer
from amrvio.sim.scene import make_scene
from amrvio.sim.simulate import SimConfig, layout_for_scene, make_camera
from amrvio.tracking.detect import DetectorConfig, detect_corners
from amrvio.types.camera import PinholeCamera
from amrvio.types.lie import SE3
from amrvio.types.sensors import ImuData

EXPOSURE_S = 0.020


@dataclass(frozen=True)
class _Frame:
    truth_px: float
    pred_px: float
    rotation_px: float
    translation_px: float


def _run(kind: str, bursts: str = "", seconds: float = 6.0) -> list[_Frame]:
    cfg = SimConfig(scene="corridor", motion=kind, seconds=seconds, fps=10.0, width=376,
                    height=240, exposure_ms=EXPOSURE_S * 1e3, blur_bursts=bursts)
    scene = make_scene("corridor", 0)
    camera = make_camera(cfg)
    renderer = SceneRenderer(scene, camera)
    motion = make_motion(kind, cfg.seconds, layout_for_scene(scene), 0, parse_blur_bursts(bursts))
    T_body_cam = default_T_body_cam(cfg.camera_pitch_deg)

    def pose_at(t: float) -> SE3:
        return motion.T_world_body(t) @ T_body_cam

    # exact gyro at 1 kHz (body frame): the rotation is the gyro's, the translation the caller's
    stamps = np.arange(0, int(seconds * 1000) + 1, dtype=np.int64) * 1_000_000
    gyro = np.array([motion.omega_body(t * 1e-9) for t in stamps])
    imu = ImuData(stamps, gyro, np.zeros_like(gyro))
    stage = FrameDiagnostics(camera=camera, T_body_cam=T_body_cam)
    det = DetectorConfig(max_corners=150, quality_level=0.01, min_distance_px=10, block_size=5)
    out = []
    for k in range(int(seconds * cfg.fps)):
        t_mid = (k + 0.5) / cfg.fps
        T_mid = pose_at(t_mid)
        depth = renderer.depth(T_mid)
        path = [pose_at(t_mid - EXPOSURE_S / 2 + EXPOSURE_S * j / 8) for j in range(9)]
        truth, _ = sim_if.predict_smear(camera, depth, T_mid, path)
        radiance = renderer.irradiance(T_mid)
        img = np.clip(radiance / np.percentile(radiance, 99) * 230.0, 0, 255).astype(np.uint8)
        pts = detect_corners(img, det)
        ij = np.rint(pts).astype(int)
        z = depth[np.clip(ij[:, 1], 0, camera.height - 1), np.clip(ij[:, 0], 0, camera.width - 1)]
        ok = np.isfinite(z) & (z > 0)
        T_c0_c1 = pose_at(t_mid - EXPOSURE_S / 2).inverse() @ pose_at(t_mid + EXPOSURE_S / 2)
        cam_motion = CameraMotion(T_c0_c1.t / EXPOSURE_S, z[ok], pts[ok])
        t_ns = int(round(t_mid * 1e9))
        h = stage.process(img, t_ns, imu.window(t_ns - 150_000_000, t_ns + 50_000_000),
                          EXPOSURE_S, motion=cam_motion)
        b = h.blur
        assert b.smear_px_pred is not None and b.smear_px_rotation is not None
        assert b.smear_px_translation is not None
        out.append(_Frame(truth, b.smear_px_pred, b.smear_px_rotation, b.smear_px_translation))
    return out


@pytest.mark.parametrize(("kind", "bursts"), [
    ("constant-velocity", ""),  # straight driving near the walls
    ("forward-stop-turn", "2.0:1.0:1.5"),  # drive, stop, turn, with a fast yaw burst
])
def test_total_smear_within_15_percent_of_simulator_truth(kind: str, bursts: str) -> None:
    frames = _run(kind, bursts)
    smeared = [f for f in frames if f.truth_px > 2.0]
    assert len(smeared) >= 25
    err = np.array([f.pred_px / f.truth_px - 1.0 for f in smeared])
    assert np.max(np.abs(err)) <= 0.15, err
    if kind == "constant-velocity":
        # the gyro alone sees almost none of it: the translation is the smear
        assert max(f.rotation_px for f in smeared) < 0.2 * min(f.truth_px for f in smeared)
        assert all(f.translation_px > 0.8 * f.truth_px for f in smeared)


def test_translational_smear_closed_form() -> None:
    """A pinhole moving sideways by t in front of a fronto-parallel plane at depth Z: every pixel
    moves by f t / Z; moving forward, a pixel at radius r from the principal point moves by
    r t / (Z - t)."""
    cam = PinholeCamera(640, 480, 500.0, 500.0, 319.5, 239.5)
    uv = np.array([[319.5, 239.5], [100.0, 50.0], [600.0, 400.0]])
    inv = np.full(3, 1.0 / 2.5)
    side = smear_at_pixels(cam, np.eye(3), uv, np.array([0.01, 0.0, 0.0]), inv)
    assert side == pytest.approx(np.full(3, 500.0 * 0.01 / 2.5), rel=1e-9)
    fwd = smear_at_pixels(cam, np.eye(3), uv, np.array([0.0, 0.0, 0.05]), inv)
    r = np.linalg.norm(uv - [319.5, 239.5], axis=1)
    assert fwd == pytest.approx(r * 0.05 / (2.5 - 0.05), rel=1e-9, abs=1e-12)
    # without depths, or without a translation, the motion is the rotation alone
    assert np.all(smear_at_pixels(cam, np.eye(3), uv) == 0.0)


def _inverse_depth_brute_force(depths: np.ndarray, pts: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The plane fit of ``CameraMotion.inverse_depth_at`` over the 8 nearest points found by
    sorting every distance (the reference for its k-d tree search)."""
    inv = 1.0 / depths
    d = np.sqrt(((q[:, None, :] - pts[None, :, :]) ** 2).sum(axis=2))
    near = np.argsort(d, axis=1)[:, :8]
    dist = np.take_along_axis(d, near, axis=1)
    rho = inv[near]
    med = np.median(rho[:, :5], axis=1)
    good = np.abs(rho - med[:, None]) <= 0.5 * med[:, None]
    w = good / (1.0 + dist / 30.0)
    out = np.empty(len(q))
    for i in range(len(q)):
        A = np.column_stack([np.ones(8), (pts[near[i]] - q[i]) / 100.0])
        plane = np.linalg.solve(A.T @ (w[i, :, None] * A) + 1e-6 * np.eye(3), A.T @ (w[i] * rho[i]))[0]
        lo, hi = rho[i][good[i]].min(), rho[i][good[i]].max()
        out[i] = np.clip(plane, lo, hi) if good[i].sum() >= 3 else med[i]
    return out


def test_inverse_depth_plane_fit_matches_a_brute_force_search() -> None:
    rng = np.random.default_rng(3)
    pts = rng.uniform([0, 0], [752, 480], size=(400, 2))
    depths = 2.0 + 0.004 * pts[:, 0] + rng.uniform(0, 1, 400) ** 4 * 20.0  # a slope, some far outliers
    q = rng.uniform([-20, -20], [772, 500], size=(300, 2))
    got = CameraMotion(np.array([0.0, 0.0, 1.0]), depths, pts).inverse_depth_at(q)
    assert got == pytest.approx(_inverse_depth_brute_force(depths, pts, q), rel=1e-9, abs=1e-12)


def test_camera_motion_depth_model_and_bad_input() -> None:
    pts = np.array([[10.0, 10.0], [12.0, 10.0], [11.0, 12.0], [300.0, 200.0], [302.0, 201.0],
                    [305.0, 199.0], [11.0, 9.0]])
    depths = np.array([1.0, 1.0, 1.0, 10.0, 10.0, 10.0, 0.01])  # one bad, far too close
    m = CameraMotion(np.array([0.0, 0.0, 1.0]), depths, pts)
    inv = m.inverse_depth_at(np.array([[11.0, 11.0], [301.0, 200.0]]))
    assert inv[0] == pytest.approx(1.0)  # the median of the 5 nearest ignores the bad depth
    assert inv[1] == pytest.approx(0.1)
    one = CameraMotion(np.zeros(3), np.array([4.0]))
    assert np.all(one.inverse_depth_at(np.zeros((3, 2))) == 0.25)
    for bad in (
        lambda: CameraMotion(np.zeros(2), np.array([1.0])),
        lambda: CameraMotion(np.zeros(3), np.array([1.0, 2.0])),
        lambda: CameraMotion(np.zeros(3), np.array([-1.0])),
        lambda: CameraMotion(np.zeros(3), np.array([1.0, 2.0]), np.zeros((3, 2))),
        lambda: CameraMotion(np.zeros(3), np.array([1.0]), omega_cam_rad_s=np.array([np.nan, 0, 0])),
    ):
        with pytest.raises(ShapeError):
            bad()


def test_exposure_advice_includes_translation() -> None:
    cam = PinholeCamera(640, 480, 500.0, 500.0, 319.5, 239.5)
    near = CameraMotion(np.array([1.0, 0.0, 0.0]), np.array([2.0]))
    # rotation-free: smear = f v T / Z = 2 px  ->  T = 2 Z / (f v) = 8 ms
    assert max_exposure_for_smear(cam, np.zeros(3), 2.0, motion=near) == pytest.approx(0.008, rel=1e-3)
    assert max_exposure_for_smear(cam, np.zeros(3), 2.0) == 1.0
