"""Simulator rendering benchmark: speed at 752x480 on one core, cost vs blur smear, accuracy.

Run alone: ``.venv/bin/python -m bench.bench_render`` (add ``--quick`` for fewer repeats).
"""

from __future__ import annotations

import functools
import math
import sys
import time
from collections.abc import Callable

import numpy as np

from amrvio.sim import textures as tx
from amrvio.sim.image_formation import CameraResponse, SensorModel, expose, render_frame
from amrvio.sim.render import SceneRenderer
from amrvio.sim.scene import Quad, Scene, make_scene
from amrvio.types.camera import CameraModel, PinholeCamera, RadTanCamera
from amrvio.types.lie import SE3, SO3

# EuRoC cam0 intrinsics (752 x 480).
PINHOLE = PinholeCamera(752, 480, 458.654, 457.296, 367.215, 248.375)
RADTAN = RadTanCamera(752, 480, 458.654, 457.296, 367.215, 248.375,
                      k1=-0.28340811, k2=0.07395907, p1=0.00019359, p2=1.76187114e-05)
R_FORWARD = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def _median_ms(fn: Callable[[], object], repeats: int) -> tuple[float, float]:
    """Median (CPU ms, wall ms) of ``fn`` over ``repeats`` calls. With cv2 on one thread, the CPU
    time is the single-core cost even when the shared machine is oversubscribed."""
    cpu, wall = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        c0 = time.process_time()
        fn()
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(cpu)), 1e3 * float(np.median(wall))


def _fixed_pose(pose: SE3, t: float) -> SE3:
    return pose


def _drive_poses(scene: Scene, n: int) -> list[SE3]:
    """Camera 0.8 m above the floor, looking ahead (slightly down), along the scene's drive."""
    out = []
    for k in range(n):
        s = scene.drive_length_m * k / max(n - 1, 1) * 0.5
        yaw = scene.start_yaw_rad + 0.15 * math.sin(0.7 * k)
        R = SO3.exp([0.0, 0.0, yaw]).R @ R_FORWARD @ SO3.exp([-0.1, 0.0, 0.0]).R
        p = scene.start_position_m + s * scene.drive_direction + np.array([0.0, 0.0, 0.8])
        out.append(SE3(SO3(R), p))
    return out


def _speed(quick: bool) -> list[dict[str, object]]:
    rows: list[dict[str, object]] = []
    n_poses = 6 if quick else 20
    for name in ("corridor", "warehouse", "room"):
        scene = make_scene(name, seed=0)
        renderer = SceneRenderer(scene, PINHOLE)
        poses = _drive_poses(scene, n_poses)
        renderer.irradiance(poses[0])  # warm-up
        times = []
        cpu = []
        for p in poses:
            t0 = time.perf_counter()
            c0 = time.process_time()
            renderer.irradiance(p)
            cpu.append(time.process_time() - c0)
            times.append(time.perf_counter() - t0)
        ms = 1e3 * float(np.median(times))
        cpu_ms = 1e3 * float(np.median(cpu))
        rows.append({"name": f"render_{name}_752x480_fps", "value": 1e3 / cpu_ms,
                     "unit": "frames/s",
                     "note": f"SceneRenderer.irradiance, pinhole, 1 thread: median CPU time "
                             f"{cpu_ms:.1f} ms/frame over {n_poses} poses (wall {ms:.1f} ms on a "
                             f"shared machine); {renderer.last_stats.pieces_drawn} pieces"})
        sensor = SensorModel()
        rng = np.random.default_rng(0)
        cpu = []
        for p in poses:
            still = functools.partial(_fixed_pose, p)
            job = functools.partial(render_frame, renderer, still, 0.0, 0.005, sensor, rng,
                                    blur=False)
            cpu.append(_median_ms(job, 1)[0])
        ms = float(np.median(cpu))
        rows.append({"name": f"frame_{name}_752x480_noblur_fps", "value": 1e3 / ms,
                     "unit": "frames/s",
                     "note": "render_frame(blur=False): render + smear prediction + exposure/noise, "
                             f"median CPU {ms:.1f} ms/frame"})
    scene = make_scene("corridor", seed=0)
    rad = SceneRenderer(scene, RADTAN)
    poses = _drive_poses(scene, n_poses)
    ms = float(np.median([_median_ms(functools.partial(rad.irradiance, p), 1)[0] for p in poses]))
    rows.append({"name": "render_corridor_752x480_radtan_fps", "value": 1e3 / ms,
                 "unit": "frames/s",
                 "note": f"EuRoC radtan, larger ideal canvas + remap: median CPU {ms:.1f} ms/frame"})
    ss = SceneRenderer(scene, PINHOLE, supersample=2)
    ms = float(np.median([_median_ms(functools.partial(ss.irradiance, p), 1)[0] for p in poses]))
    rows.append({"name": "render_corridor_752x480_supersample2_fps", "value": 1e3 / ms,
                 "unit": "frames/s",
                 "note": f"anti-aliased (2x2 sub-pixels): median CPU {ms:.1f} ms/frame"})
    return rows


def _blur_cost(quick: bool) -> list[dict[str, object]]:
    rows: list[dict[str, object]] = []
    scene = make_scene("corridor", seed=0)
    renderer = SceneRenderer(scene, PINHOLE)
    base = _drive_poses(scene, 3)[1]
    T_exp = 0.01
    sensor = SensorModel()
    for target_px in (0.0, 5.0, 10.0, 20.0, 40.0) if not quick else (0.0, 10.0, 40.0):
        omega = target_px / (PINHOLE.fx * T_exp)

        def pose_at(t: float, omega: float = omega) -> SE3:
            return base @ SE3(SO3.exp([0.0, omega * (t - T_exp / 2), 0.0]), np.zeros(3))

        rng = np.random.default_rng(0)
        job = functools.partial(render_frame, renderer, pose_at, 0.0, T_exp, sensor, rng,
                                blur=True)
        ms = _median_ms(job, 2 if quick else 3)[0]
        fr = job()
        rows.append({"name": f"blur_cost_smear_{target_px:.0f}px_ms", "value": ms, "unit": "ms",
                     "note": f"CPU per frame; corridor 752x480, yaw rate {omega:.2f} rad/s, T=10 ms: "
                             f"{fr.n_subframes} sub-frames, predicted smear centre "
                             f"{fr.smear_px_center:.1f} px, max {fr.smear_px_max:.1f} px"})
    return rows


def _corner_errors(camera: CameraModel) -> tuple[float, float]:
    import cv2

    tex = tx.checkerboard(256, 16)
    c0 = np.array([0.0, -3.0, -2.0])
    a, b = np.array([0.0, 6.0, 0.0]), np.array([0.0, 0.0, 4.0])
    Rz = SO3.exp([0.0, 0.0, 0.45]).R
    corners = np.stack([c0, c0 + a, c0 + a + b, c0 + b]) @ Rz.T + np.array([4.0, 0.0, 1.0])
    wall = Quad(corners, 0, 64.0, 1.0, (-0.5, -0.5))
    scene = Scene("checker", (wall,), (tex,), corners.min(0), corners.max(0))
    T = SE3(SO3(R_FORWARD @ SO3.exp([0.08, -0.05, 0.03]).R), np.array([0.3, 0.2, 1.1]))
    img = SceneRenderer(scene, camera).irradiance(T)
    X = np.array([wall.point_at(16 * k - 0.5, 16 * m - 0.5) for k in range(1, 24)
                  for m in range(1, 16)])
    uv = camera.project(T.inverse().act(X))
    uv = uv[camera.in_image(uv, 15.0)]
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-4)
    found = cv2.cornerSubPix(img, (uv + 0.7).astype(np.float32).reshape(-1, 1, 2), (5, 5),
                             (-1, -1), crit).reshape(-1, 2)
    err = np.linalg.norm(found - uv, axis=1)
    return float(np.median(err)), float(err.max())


CAM_CENTRED = PinholeCamera(752, 480, 458.654, 457.296, 375.5, 239.5)


def _edge_scene() -> Scene:
    """A wall 3 m ahead (camera-frame z = 3), dark for x < 0 and bright for x > 0."""
    quads = []
    for x0, tid in ((-4.0, 0), (0.0, 1)):
        c0 = np.array([x0, -3.0, 3.0])
        a, b = np.array([4.0, 0.0, 0.0]), np.array([0.0, 6.0, 0.0])
        quads.append(Quad(np.stack([c0, c0 + a, c0 + a + b, c0 + b]), tid, 100.0, 100.0))
    corners = np.concatenate([q.corners_world for q in quads])
    return Scene("edge", tuple(quads), (tx.constant(8, 0.1), tx.constant(8, 0.9)),
                 corners.min(0), corners.max(0))


def _edge_variance(img: np.ndarray) -> float:
    """Variance (px^2) of the edge's derivative profile; a box blur of length L adds L^2 / 12."""
    prof = img[200:280].astype(np.float64).mean(axis=0)
    d = np.clip(np.diff(prof)[300:450], 0.0, None)
    x = np.arange(d.size) + 0.5
    m = (d * x).sum() / d.sum()
    return float((d * (x - m) ** 2).sum() / d.sum())


def _accuracy() -> list[dict[str, object]]:
    rows: list[dict[str, object]] = []
    for cam, label in ((PINHOLE, "pinhole"), (RADTAN, "radtan")):
        med, mx = _corner_errors(cam)
        rows.append({"name": f"reprojection_{label}_median_px", "value": med, "unit": "px",
                     "note": f"checker corners: cornerSubPix vs camera.project, max {mx:.3f} px"})
    # Blur smear vs f w T on a step edge (pure rotation), as in tests/sim/test_image_formation.py.
    renderer = SceneRenderer(_edge_scene(), CAM_CENTRED)
    for omega in (2.0, 4.0, 8.0):
        def pose_at(t: float, omega: float = omega) -> SE3:
            return SE3(SO3.exp([0.0, omega * (t - 0.005), 0.0]), np.zeros(3))

        s = SensorModel.ideal(1.0)
        sharp = render_frame(renderer, pose_at, 0.0, 0.01, s, None, blur=False).image
        blurred = render_frame(renderer, pose_at, 0.0, 0.01, s, None, blur=True).image
        L = math.sqrt(12.0 * (_edge_variance(blurred) - _edge_variance(sharp)))
        ref = CAM_CENTRED.fx * omega * 0.01
        rows.append({"name": f"smear_ratio_w{omega:.0f}", "value": L / ref, "unit": "ratio",
                     "note": f"measured edge smear {L:.2f} px / f w T {ref:.2f} px"})
    return rows


def run(quick: bool) -> list[dict[str, object]]:
    import cv2

    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)  # one core, as the issue asks
    try:
        rows = _speed(quick) + _blur_cost(quick) + _accuracy()
    finally:
        cv2.setNumThreads(threads)
    # Exposure alone, for reference.
    img = np.random.default_rng(0).random((480, 752), dtype=np.float32) * 100
    rng = np.random.default_rng(1)
    ms = _median_ms(lambda: expose(img, 0.005, SensorModel(response=CameraResponse(2.2)), rng),
                    5 if quick else 20)[0]
    rows.append({"name": "expose_752x480_ms", "value": ms, "unit": "ms",
                 "note": "CPU: vignette, shot + read noise, gamma-2.2 response, 8-bit"})
    return rows


if __name__ == "__main__":
    for row in run("--quick" in sys.argv):
        print(f"{row['name']:<40} {row['value']:10.3f} {row['unit']:<9} {row['note']}")
