"""The VO on the motions it used to fail on (issue 9), each simulated with ground truth and run
with the default configuration: a camera facing one plane (homography initialisation), a robot
already turning at the first frame, a robot that turns in place, and two runs whose lens is
covered for one second in the middle (the map must be found again, one map and one scale).

The sequences are small (376x240 or 8 s) to keep the suite fast; bench/bench_protocol.py runs
the full-size protocol.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from amrvio.config import PipelineConfig
from amrvio.eval.evaluate import evaluate
from amrvio.frontend.tracking_types import TrackOutcome
from amrvio.io.dataset import open_dataset
from amrvio.pipeline.pipeline import PipelineOutput
from amrvio.pipeline.records import PoseStatus
from amrvio.pipeline.run import run_pipeline
from amrvio.sim.simulate import SimConfig, simulate
from amrvio.types.trajectory import Trajectory


def _run(tmp: Path, **sim: object) -> tuple[PipelineOutput, float]:
    """Simulate, run the VO with the default configuration (the IMU off: these are the VO's
    properties; tests/test_vio_pipeline.py runs the VIO); (output, Sim3 ATE % of the path)."""
    simulate(SimConfig(**{"fps": 20.0, "blur": False, **sim}), tmp / "seq")  # type: ignore[arg-type]
    ds = open_dataset(str(tmp / "seq"))
    if ds.groundtruth is None or ds.T_body_cam is None:
        raise AssertionError("the simulator wrote no ground truth")
    gt = ds.groundtruth.right_multiplied(ds.T_body_cam)
    cfg = PipelineConfig()
    out = run_pipeline(ds, dataclasses.replace(cfg, vio=dataclasses.replace(cfg.vio, enabled=False)))
    est = Trajectory.from_matrices(out.stamps_ns * 1e-9, out.T_world_cam)
    res = evaluate(est, gt, align="sim3")
    return out, 100.0 * res.ate.rmse / res.path_length_m


def _init_frame(out: PipelineOutput) -> int:
    return next(i for i, r in enumerate(out.records) if any(e.startswith("init_ok") for e in r.events))


def _tracked(out: PipelineOutput) -> float:
    return sum(r.status is PoseStatus.TRACKED for r in out.records) / len(out.records)


def test_a_camera_facing_one_wall_initialises_from_the_homography(tmp_path: Path) -> None:
    out, ate = _run(tmp_path, scene="wall", motion="wall-scan", seconds=5.0, width=376, height=240)
    init = out.records[_init_frame(out)].estimator.init
    assert init is not None and init.model.value == "homography"
    assert _init_frame(out) <= 10
    assert _tracked(out) >= 0.98
    assert ate <= 1.0


def test_a_robot_already_turning_initialises_at_once(tmp_path: Path) -> None:
    out, ate = _run(tmp_path, scene="room", motion="start-in-turn", seconds=5.0, width=376,
                    height=240)
    assert _init_frame(out) <= 10
    assert _tracked(out) >= 0.98
    assert ate <= 1.0


def test_a_turn_in_place_is_tracked_and_keeps_the_scale(tmp_path: Path) -> None:
    out, ate = _run(tmp_path, scene="warehouse", motion="turn-in-place", seconds=8.0, width=376,
                    height=240)
    # the turn (about 3.75-5.75 s) is tracked, in the one map of the run
    turn = [r for r in out.records if 3.9 <= r.t_ns * 1e-9 - out.records[0].t_ns * 1e-9 <= 5.6]
    assert turn and all(r.status is PoseStatus.TRACKED for r in turn)
    assert {r.segment for r in out.records if r.segment is not None} == {0}
    assert _tracked(out) >= 0.98
    assert ate <= 1.0


@pytest.mark.parametrize(("scene", "motion", "blackout", "seed"), [
    ("corridor", "forward-stop-turn", "4.5:1.0", 0),
    ("warehouse", "rough-floor", "4.0:1.0", 0),
    # the robot turns 28 degrees in the dark and the map search fails at the first frame after
    # it; direct alignment from the stale motion posed that frame 27 degrees off, the map grew in
    # that frame (5.6 % ATE); now the frame is lost and the next one is found in the map
    ("corridor", "forward-stop-turn", "4.5:1.0", 2),
])
def test_after_a_one_second_black_out_the_map_is_found_again(tmp_path: Path, scene: str,
                                                              motion: str, blackout: str, seed: int) -> None:
    out, ate = _run(tmp_path, scene=scene, motion=motion, seconds=8.0 if scene == "warehouse"
                    else 10.0, width=752, height=480, blackouts=blackout, seed=seed)
    t0, dur = (float(v) for v in blackout.split(":"))
    t = np.array([r.t_ns for r in out.records]) * 1e-9
    t -= t[0] - 0.025  # frame k is stamped at (k + 1/2) / fps
    dark = [r for r, tk in zip(out.records, t, strict=True) if t0 <= tk < t0 + dur]
    assert dark and all("no_signal" in r.events for r in dark[1:-1])
    after = [r for r, tk in zip(out.records, t, strict=True) if tk >= t0 + dur + 0.1]
    # tracking resumes in the same map: no new segment, no scale guess
    assert all(r.segment == 0 and r.status is PoseStatus.TRACKED for r in after)
    assert not any(e.startswith("segment_scale_guess") for r in out.records for e in r.events)
    assert ate <= 1.5


def test_after_blurred_frames_that_pnp_posed_the_map_is_not_searched(tmp_path: Path) -> None:
    """bench_vo's corridor (752x480, 10 s, 3 EV steps, 2 blur bursts of 0.5 s): PnP poses the
    frames of a burst from the last sharp image, so the motion model is still fresh when the burst
    ends, and the map is not searched (Tracker.stale). Searching it there, as before, gave 0.38 %
    Sim3 ATE instead of 0.088 %."""
    t = 10.0
    out, ate = _run(tmp_path, scene="corridor", motion="forward-stop-turn", seconds=t, width=752,
                    height=480, ev_steps=f"{0.2 * t:.2f}:+1,{0.45 * t:.2f}:-1.5,{0.7 * t:.2f}:+1",
                    blur_bursts=f"{0.3 * t:.2f}:0.5:3,{0.6 * t:.2f}:0.5:3", blur=True)
    posed = [r.index for r in out.records if r.tracking is not None
             and r.tracking.outcome in (TrackOutcome.TRACKED_BLURRED, TrackOutcome.BLURRED_REFERENCE)]
    assert len(posed) >= 5, "no burst that PnP poses: the case no longer tests what it guards"
    assert not any(e.startswith("reloc") for r in out.records for e in r.events)
    assert ate <= 0.2
