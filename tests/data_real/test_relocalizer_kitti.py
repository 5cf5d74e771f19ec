"""Relocalisation on KITTI 00 against ground truth: a map of keyframes 0, 2 and 4 (GT poses, corners
tracked by OpenCV's KLT and triangulated between frames 0 and 4), then frames that are not in the
database are relocalised in it; a frame of another street, and noise, must not be."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from numpy.typing import NDArray

from amrvio.estimator.keyframe_db import KeyframeDatabase
from amrvio.estimator.relocalizer import RelocStatus, relocalize
from amrvio.estimator.vo_map import VoMap
from amrvio.geometry.projection import pixels_to_normalized
from amrvio.geometry.triangulation import triangulate
from amrvio.io.base import Dataset
from amrvio.io.dataset import open_dataset
from amrvio.types.lie import se3_matrix_inverse
from tests.skip_policy import skip_shared_missing

pytestmark = pytest.mark.real_data

F64 = NDArray[np.float64]
KITTI = "kitti00_0000-0199"
KEYFRAMES = (0, 2, 4)


class _KittiMap:
    """The map of KEYFRAMES with ground-truth poses; ``T_cw(i)``: GT ``T_cam_world`` of frame i."""

    def __init__(self, ds: Dataset) -> None:
        cam, gt = ds.camera, ds.groundtruth
        assert cam is not None and gt is not None
        self.ds = ds
        self.K = np.array([[cam.fx, 0.0, cam.cx], [0.0, cam.fy, cam.cy], [0.0, 0.0, 1.0]])
        self.T_world_cam = gt.matrices()
        imgs = {i: ds.frames[i].load() for i in range(KEYFRAMES[-1] + 1)}
        p0 = cv2.goodFeaturesToTrack(imgs[0], 1500, 0.001, 10, blockSize=5).reshape(-1, 2)
        ids = np.arange(len(p0))
        pts: dict[int, F64] = {0: p0.astype(np.float64)}
        alive = {0: np.ones(len(p0), dtype=bool)}
        ok = np.ones(len(p0), dtype=bool)
        p = p0.astype(np.float32)
        for i in range(1, KEYFRAMES[-1] + 1):  # KLT with a forward-backward check
            p1, st, _ = cv2.calcOpticalFlowPyrLK(imgs[i - 1], imgs[i], p, None, winSize=(21, 21),
                                                 maxLevel=3)
            pb, stb, _ = cv2.calcOpticalFlowPyrLK(imgs[i], imgs[i - 1], p1, None, winSize=(21, 21),
                                                   maxLevel=3)
            ok &= (st.ravel() == 1) & (stb.ravel() == 1) & (np.linalg.norm(pb - p, axis=1) < 0.5)
            p = p1
            pts[i], alive[i] = p.astype(np.float64), ok.copy()
        a, b = KEYFRAMES[0], KEYFRAMES[-1]
        tri = triangulate(self.T_cw(a), self.T_cw(b), pixels_to_normalized(pts[a], self.K),
                          pixels_to_normalized(pts[b], self.K), min_parallax_deg=0.5,
                          max_reproj_px=2.0, focal_px=float(self.K[0, 0]))
        good = tri.valid & alive[b]
        self.vm, self.db = VoMap(), KeyframeDatabase()
        self.vm.set_points(ids[good], tri.points_world[good])
        self.baseline_m = float(np.linalg.norm(self.T_world_cam[b][:3, 3] - self.T_world_cam[a][:3, 3]))
        for k in KEYFRAMES:
            sel = alive[k]
            kf = self.vm.add_keyframe(k, self.T_cw(k), ids[sel], pts[k][sel])
            self.db.add(kf.kf_id, imgs[k], pts[k][sel], ids[sel], priority=self.vm.points_of(ids[sel]))
        self.n_points = int(good.sum())

    def T_cw(self, i: int) -> F64:
        return se3_matrix_inverse(self.T_world_cam[i])


@pytest.fixture(scope="module")
def kitti_map(shared_data: Path) -> _KittiMap:
    root = shared_data / KITTI
    if not root.is_dir():
        skip_shared_missing(root)
    return _KittiMap(open_dataset(f"kitti:{root}"))


@pytest.mark.parametrize(("frame", "max_pos_m"), [(3, 0.10), (5, 0.15), (6, 0.25)])
def test_kitti_frame_relocalised_against_ground_truth(kitti_map: _KittiMap, frame: int,
                                                      max_pos_m: float) -> None:
    """Frame 3 lies between keyframes, 5 and 6 are 0.9 and 1.7 m past the last one (the car drives
    0.86 m per frame; the map's points come from GT poses, whose own error is a few cm)."""
    m = kitti_map
    assert m.n_points > 300 and m.baseline_m == pytest.approx(3.43, abs=0.05)
    res = relocalize(m.ds.frames[frame].load(), m.K, m.vm, m.db, seed=0)
    assert res.status is RelocStatus.OK
    assert res.T_cam_world is not None and res.n_inliers >= 50
    T_true = m.T_cw(frame)
    dR = res.T_cam_world[:3, :3] @ T_true[:3, :3].T
    rot_deg = float(np.degrees(np.arccos(np.clip((np.trace(dR) - 1) / 2, -1, 1))))
    centre = -res.T_cam_world[:3, :3].T @ res.T_cam_world[:3, 3]
    pos_m = float(np.linalg.norm(centre - m.T_world_cam[frame][:3, 3]))
    assert rot_deg < 1.0 and pos_m < max_pos_m, (rot_deg, pos_m)
    assert np.all(m.vm.points_of(res.point_ids)) and res.uv.shape == (len(res.point_ids), 2)


def test_kitti_other_street_and_noise_are_not_relocalised(kitti_map: _KittiMap) -> None:
    m = kitti_map
    far = relocalize(m.ds.frames[190].load(), m.K, m.vm, m.db, seed=0)  # 140 m down the road
    assert far.status in (RelocStatus.TOO_FEW_MATCHES, RelocStatus.PNP_FAILED)
    assert far.T_cam_world is None and far.n_inliers < 30
    noise = np.random.default_rng(0).integers(0, 256, (376, 1241), dtype=np.uint8)
    res = relocalize(noise, m.K, m.vm, m.db, seed=0)
    assert res.status in (RelocStatus.TOO_FEW_MATCHES, RelocStatus.PNP_FAILED)
