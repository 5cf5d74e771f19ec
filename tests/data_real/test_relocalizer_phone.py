"""Relocalisation on the hand-held phone's 1080p frames (heavy real blur): the keyframe database and
the query are described on the image the tracker works on (one pyramid level down, 960 wide).

The map is the VO's own over frames 0-17 (one segment); each frame that is not a keyframe is then
searched in it, with the keyframes described once at full resolution and once reduced as the
tracker reduces them. Measured: full resolution finds 1 of the 9 frames (ORB's patch on the
blurred 1080p image matched the keyframes at a median reprojection error of mostly 150-900 px at the
tracked pose), reduced 3 (frames 7, 10 and 12), each within 0.07 map units of the VO's own pose
(keyframes 0.26-1.0 units apart)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from amrvio.config import PipelineConfig
from amrvio.io.dataset import open_dataset
from amrvio.pipeline.pipeline import Pipeline
from amrvio.pipeline.recovery import MapRecovery
from amrvio.types.lie import se3_matrix_inverse

pytestmark = pytest.mark.real_data

N = 18


def _found(pipe: Pipeline, images: list[NDArray[np.uint8]], K: NDArray[np.float64],
           max_width_px: int | None) -> dict[int, NDArray[np.float64]]:
    """Frame index -> relocalised camera centre (map frame) of the frames that are not keyframes."""
    vomap = pipe.mapping.segments[0].mapper.map
    rec = MapRecovery(K, pipe.recovery.cfg, 0, max_width_px)  # its gates in image pixels
    kf_frames = {kf.frame_index for kf in vomap.keyframes}
    for kf in vomap.keyframes:
        if len(kf.track_ids):  # a keyframe that left the BA window keeps no tracks
            rec.add_keyframe(0, kf.kf_id, images[kf.frame_index], vomap)
    found = {}
    for i in range(N):
        if i in kf_frames:
            continue
        rec.lost(0)
        res = rec.attempt(images[i], vomap, i)
        assert res is not None
        if res.ok and res.T_cam_world is not None:
            found[i] = se3_matrix_inverse(res.T_cam_world)[:3, 3]
    return found


def test_blurred_1080p_frames_are_found_at_the_tracking_level(shared_data: Path) -> None:
    root = shared_data / "phone_handheld_blur_0450-0549"
    ds = open_dataset(str(root), root / "calib_claimed" / "live.yaml")
    cam = ds.camera
    assert cam is not None and cam.width == 1920
    cfg = PipelineConfig()
    pipe = Pipeline(cam, dataclasses.replace(cfg, vio=dataclasses.replace(cfg.vio, enabled=False)))
    images = []
    for fr in ds.frames[:N]:
        img = fr.load()
        pipe.process(img, fr.t_ns)
        images.append(np.asarray(cam.undistort_image(img), dtype=np.uint8))
    assert len(pipe.mapping.segments) == 1, "the first 18 frames no longer make one map: pick others"
    K = np.asarray(cam.pinhole().K, dtype=np.float64)
    reduced = _found(pipe, images, K, cfg.tracking.klt.max_width_px)
    full = _found(pipe, images, K, None)
    assert len(reduced) >= 3 and len(reduced) > len(full), (sorted(reduced), sorted(full))
    # segment 0's world is its map frame: the relocalised pose is the VO's own
    for i, c in reduced.items():
        pose = pipe.records[i].pose_online
        assert pose is not None
        assert np.linalg.norm(c - pose.t) < 0.15, i
