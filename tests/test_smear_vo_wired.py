"""The translational smear inside ``amrvio run`` against the simulator's true smear in the 2.4 m
corridor with 20 ms exposures: driving straight at 1 m/s, where the gyro sees almost none of the
smear and the VO's own motion gives it (velocity from its tracked poses, depths from its map
points; the VIO cannot start at constant velocity); and forward-stop-turn with a yaw burst, where
the VO loses the frames of the burst and the VIO's prediction (velocity, landmarks) gives it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import amrvio
from amrvio.pipeline.records import PoseStatus
from amrvio.sim.simulate import SimConfig, simulate
from amrvio.sim.writer import read_frames_csv


@pytest.fixture(scope="module")
def corridor(tmp_path_factory: pytest.TempPathFactory) -> Path:
    seq = tmp_path_factory.mktemp("smear") / "seq"
    simulate(SimConfig(scene="corridor", motion="constant-velocity", seconds=6.0, fps=10.0,
                       width=376, height=240, exposure_ms=20.0), seq)
    return seq


def test_vo_motion_gives_the_translational_smear(corridor: Path) -> None:
    res = amrvio.run(corridor, report=False)
    truth = read_frames_csv(corridor / "sim_frames.csv")
    recs = res.output.records
    assert len(recs) == len(truth) == 60
    # the map (and the first two tracked poses) exists from the frame that initialised it
    first_map = next(r.index for r in recs if any(e.startswith("init_ok") for e in r.events))
    assert first_map <= 5 and all(r.status is PoseStatus.TRACKED for r in recs[first_map:])
    errs, rot_share = [], []
    for rec, tr in zip(recs, truth, strict=True):
        b = rec.diagnostics.blur if rec.diagnostics is not None else None
        if rec.index <= first_map or tr.smear_px_max <= 2.0 or b is None:
            continue
        assert b.smear_px_pred is not None and b.smear_px_rotation is not None
        assert b.smear_px_translation is not None, f"frame {rec.index}: no translational part"
        errs.append(b.smear_px_pred / tr.smear_px_max - 1.0)
        rot_share.append(b.smear_px_rotation / tr.smear_px_max)
    errs_a = np.abs(np.array(errs))
    assert len(errs) >= 50
    assert max(rot_share) < 0.1  # the gyro alone would miss nearly all of it
    assert np.median(errs_a) < 0.05
    assert np.all(errs_a <= 0.15), np.round(np.array(errs), 3)


def test_the_vio_gives_the_translational_smear_through_a_blur_burst(tmp_path: Path) -> None:
    seq = tmp_path / "fst"
    simulate(SimConfig(scene="corridor", motion="forward-stop-turn", seconds=6.0, fps=10.0,
                       width=376, height=240, exposure_ms=20.0, blur_bursts="2.0:1.0:1.5"), seq)
    recs = amrvio.run(seq, report=False).output.records
    truth = read_frames_csv(seq / "sim_frames.csv")
    first_map = next(r.index for r in recs if any(e.startswith("init_ok") for e in r.events))
    errs, bridged = [], 0
    for rec, tr in zip(recs, truth, strict=True):
        b = rec.diagnostics.blur if rec.diagnostics is not None else None
        if rec.index <= first_map or tr.smear_px_max <= 2.0 or b is None:
            continue
        assert b.smear_px_pred is not None
        assert b.smear_px_translation is not None, f"frame {rec.index}: no translational part"
        errs.append(b.smear_px_pred / tr.smear_px_max - 1.0)
        bridged += rec.status is PoseStatus.BRIDGED
    errs_a = np.abs(np.array(errs))
    assert len(errs) >= 25 and bridged >= 4  # the burst: the VO lost it, the IMU bridged it
    assert np.median(errs_a) < 0.05
    assert np.all(errs_a <= 0.15), np.round(np.array(errs), 3)
