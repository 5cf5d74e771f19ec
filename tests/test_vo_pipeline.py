"""VO pipeline on a small synthetic sequence rendered here: poses for every frame, accuracy,
determinism, and the typed statuses."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import cv2
import numpy as np
import pytest
from skimage import data as skdata

from amrvio.config import PipelineConfig
from amrvio.pipeline.pipeline import Pipeline
from amrvio.pipeline.record_log import RecordLog
from amrvio.pipeline.records import PoseStatus
from amrvio.types.lie import se3_matrix as rt_to_T
from amrvio.types.lie import se3_matrix_inverse as invert_T
from amrvio.types.lie import so3_exp as so3_exp_small

W, H = 320, 240
K = np.array([[260.0, 0, 159.5], [0, 260.0, 119.5], [0, 0, 1]])


def _world_texture() -> np.ndarray:
    tex = np.asarray(skdata.grass(), dtype=np.uint8)
    return cv2.GaussianBlur(tex, (0, 0), 1.0)


def _render_box(T_cam_world: np.ndarray, tex: np.ndarray) -> np.ndarray:
    """Camera inside a textured box: walls x=+-4, floor y=+1.5, ceiling y=-2.5, end z=30."""
    uu, vv = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
    d_c = np.stack([(uu - K[0, 2]) / K[0, 0], (vv - K[1, 2]) / K[1, 1], np.ones_like(uu)], -1)
    T_wc = invert_T(T_cam_world)
    d = d_c @ T_wc[:3, :3].T
    o = T_wc[:3, 3]
    best = np.full(uu.shape, np.inf)
    s_coord = np.zeros(uu.shape)
    t_coord = np.zeros(uu.shape)
    for axis, val, (a1, a2) in [(0, -4.0, (2, 1)), (0, 4.0, (2, 1)), (1, 1.5, (0, 2)),
                                (1, -2.5, (0, 2)), (2, 30.0, (0, 1))]:
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = (val - o[axis]) / d[..., axis]
        lam = np.where(lam > 0, lam, np.inf)
        hit = lam < best
        P = o + lam[..., None] * d
        best = np.where(hit, lam, best)
        s_coord = np.where(hit, P[..., a1] + 7.0 * axis, s_coord)
        t_coord = np.where(hit, P[..., a2] + 3.0 * axis, t_coord)
    ppm = 60.0  # texture pixels per metre
    mx = np.mod(s_coord * ppm, tex.shape[1] - 1).astype(np.float32)
    my = np.mod(t_coord * ppm, tex.shape[0] - 1).astype(np.float32)
    return cv2.remap(tex, mx, my, cv2.INTER_LINEAR)


def _sequence(n: int) -> tuple[list[np.ndarray], np.ndarray]:
    tex = _world_texture()
    poses = []
    for k in range(n):
        yaw = 0.15 * np.sin(0.08 * k)
        T_wc = rt_to_T(so3_exp_small(np.array([0.0, yaw, 0.0])),
                       np.array([0.8 * np.sin(0.05 * k), 0.0, 0.15 * k]))
        poses.append(T_wc)
    imgs = [_render_box(invert_T(T), tex) for T in poses]
    return imgs, np.stack(poses)


@pytest.fixture(scope="module")
def seq() -> tuple[list[np.ndarray], np.ndarray]:
    return _sequence(40)


def _run(imgs: list[np.ndarray]) -> np.ndarray:
    cfg = PipelineConfig()
    vo = Pipeline(K, cfg)
    for i, im in enumerate(imgs):
        vo.process(im, i * 50_000_000)
    out = vo.finish()
    assert all(f.status is not PoseStatus.LOST for f in out.records)
    return out.T_world_cam


def _sim3_ate(est: np.ndarray, gt: np.ndarray) -> float:
    mx, my = est.mean(0), gt.mean(0)
    xc, yc = est - mx, gt - my
    U, d, Vt = np.linalg.svd(yc.T @ xc / len(est))
    D = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        D[2, 2] = -1
    R = U @ D @ Vt
    s = np.trace(np.diag(d) @ D) / xc.var(0).sum()
    e = (s * est @ R.T + (my - s * R @ mx)) - gt
    return float(np.sqrt(np.mean(np.sum(e * e, axis=1))))


def test_vo_synthetic_box_every_frame_has_accurate_pose(
        seq: tuple[list[np.ndarray], np.ndarray]) -> None:
    imgs, gt = seq
    T = _run(imgs)
    assert T.shape == (len(imgs), 4, 4)
    assert np.all(np.isfinite(T))
    path = float(np.sum(np.linalg.norm(np.diff(gt[:, :3, 3], axis=0), axis=1)))
    assert _sim3_ate(T[:, :3, 3], gt[:, :3, 3]) < 0.01 * path


def test_vo_is_deterministic(seq: tuple[list[np.ndarray], np.ndarray]) -> None:
    imgs, _ = seq
    a = _run(imgs[:25])
    b = _run(imgs[:25])
    assert np.array_equal(a, b)


def test_vo_static_camera_reports_lost_not_nan() -> None:
    tex = _world_texture()
    img = _render_box(np.eye(4), tex)
    vo = Pipeline(K)
    for i in range(5):
        r = vo.process(img, i * 50_000_000)
        assert r.pose_online is not None and np.all(np.isfinite(r.pose_online.matrix()))
    out = vo.finish()
    assert all(f.status is PoseStatus.LOST for f in out.records)
    assert np.all(np.isfinite(out.T_world_cam))


def test_vo_blurred_frames_are_not_keyframes_and_exposure_step_keeps_tracking(
        seq: tuple[list[np.ndarray], np.ndarray]) -> None:
    imgs, gt = seq
    imgs = [im.copy() for im in imgs]
    blurred = {22, 23}
    for k in blurred:
        imgs[k] = cv2.GaussianBlur(imgs[k], (0, 0), 4.0)
    for k in range(28, len(imgs)):  # exposure step: +0.7 EV, gain and offset
        imgs[k] = np.clip(1.6 * imgs[k].astype(np.float64) - 20, 0, 255).astype(np.uint8)
    vo = Pipeline(K)
    results = [vo.process(im, i * 50_000_000) for i, im in enumerate(imgs)]
    for k in blurred:
        assert results[k].blurred
        assert not results[k].is_keyframe
    out = vo.finish()
    assert all(f.status is PoseStatus.TRACKED for f in out.records[5:])
    assert not any(e.startswith("lost") for r in out.records for e in r.events)
    tr30, tr28 = out.records[30].tracking, results[28].tracking
    assert tr30 is not None and tr28 is not None
    assert abs(tr30.brightness_a - 1.0) < 0.05  # after the step: back to ~1
    assert abs(tr28.brightness_a - 1.6) < 0.1
    path = float(np.sum(np.linalg.norm(np.diff(gt[:, :3, 3], axis=0), axis=1)))
    assert _sim3_ate(out.T_world_cam[:, :3, 3], gt[:, :3, 3]) < 0.01 * path


def test_run_memory_is_bounded_records_on_disk_and_old_tracks_dropped(
        seq: tuple[list[np.ndarray], np.ndarray], tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    imgs, _ = seq
    cfg = PipelineConfig()
    vo = Pipeline(K, cfg)
    online = [vo.process(im, i * 50_000_000) for i, im in enumerate(imgs)]
    out = vo.finish()
    # the records: every frame once, in order, the online record with its final status and pose
    assert isinstance(out.records, RecordLog) and len(out.records) == len(imgs)
    assert [r.index for r in out.records] == list(range(len(imgs)))
    assert np.array_equal(out.stamps_ns, [r.t_ns for r in online])
    for a, b in zip(online, out.records, strict=True):
        assert (a.events, a.blur, a.tracking, a.estimator) == (b.events, b.blur, b.tracking, b.estimator)
        assert b.pose_refined is not None and np.array_equal(b.pose_refined.matrix(), out.T_world_cam[b.index])
    # read back from the file: the newest two in memory, the rest unpickled, equal to what was written
    log = RecordLog(online, keep=2)
    assert log == online and log[-1] is online[-1] and log[0] is not online[0]
    assert log != [*online[:-1], dataclasses.replace(online[-1], events=("x",))] and log != online[1:]
    assert [r.index for r in log[3:9:2]] == [3, 5, 7] and log[-len(online)].index == 0
    with pytest.raises(IndexError):
        log[len(online)]
    log.close()
    assert log[-1] is online[-1]  # kept in memory
    with pytest.raises(ValueError, match="closed file"):
        log[0]
    # no writable temporary folder: the same records, kept in memory
    held = RecordLog(online, keep=2, directory=str(tmp_path / "missing"))
    assert held == online and "in memory" in caplog.text
    # the keyframes that left the BA window keep their pose and drop their tracks
    mcfg = cfg.mapping.mapper
    kfs = vo.mapping.current.mapper.map.keyframes
    window = mcfg.ba_window + mcfg.ba_fixed
    assert len(kfs) > window + 2
    assert all(len(k.track_ids) == 0 and k.uv.shape == (0, 2) for k in kfs[:-window])
    assert all(len(k.track_ids) > 50 and len(k.uv) == len(k.track_ids) for k in kfs[-window:])
    kf_frames = [k.frame_index for k in kfs]
    assert np.all(np.isfinite(out.T_world_cam[kf_frames]))
