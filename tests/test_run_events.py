"""events.jsonl from frame records (amrvio.pipeline.events), on records made here: each event
string becomes one line with its report, attempts and keyframes get lines, dropped ranges and
their causes, flag ranges, strict JSON."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from amrvio.diagnostics.blur import BlurResult
from amrvio.diagnostics.health import BlurHealth, ExposureHealth, FrameHealth, ParallaxHealth
from amrvio.estimator.camera_height import HeightEstimate
from amrvio.estimator.initializer import InitResult
from amrvio.estimator.local_ba import BAReport, BAStatus
from amrvio.estimator.local_mapping import KeyframeReport
from amrvio.estimator.mapper import TriangulationReport
from amrvio.frontend.keyframe_policy import KeyframeReason
from amrvio.frontend.tracking_types import TrackingReport, TrackOutcome
from amrvio.geometry.ground_plane import PlaneStatus
from amrvio.geometry.two_view import TwoViewModel, TwoViewStatus
from amrvio.io.base import SkippedFrame
from amrvio.pipeline.events import (
    dropped_events,
    event_line,
    flag_ranges,
    flagged_ranges,
    frame_events,
    jsonable,
    run_events,
)
from amrvio.pipeline.records import EstimatorReport, FrameRecord, PoseStatus
from amrvio.types.lie import so3_exp


def _health(i: int, blur: bool = False, ev: float = 0.0, low_par: bool = False) -> FrameHealth:
    return FrameHealth(
        t_ns=i * 10**8, frame=i,
        blur=BlurHealth(var_lap=100.0, score=1.0, ratio=0.3 if blur else 1.0, flag=blur),
        exposure=ExposureHealth(None, 1.0, 0.0, ev, abs(ev) > 0.3, "klt", 0.0, 0.0),
        parallax=ParallaxHealth(1.0, low_par, 100, "klt", False))


def _init(status: TwoViewStatus, ref: int, T: np.ndarray | None = None) -> InitResult:
    return InitResult(status, TwoViewModel.ESSENTIAL, ref, 300, 0.8, 1.2, 4.0,
                      250 if status is TwoViewStatus.OK else 0, False,
                      status is not TwoViewStatus.OK and status is not TwoViewStatus.LOW_PARALLAX, T)


def _rec(i: int, status: PoseStatus = PoseStatus.TRACKED, events: tuple[str, ...] = (),
         est: EstimatorReport | None = None, segment: int | None = 0, **health: object) -> FrameRecord:
    tr = TrackingReport(TrackOutcome.TRACKED, 200, 150, 1.0, 0.0, False, "ok")
    return FrameRecord(i, i * 10**8, status, None, None, segment, 1.0, events,
                       BlurResult(1.0, 1.0, 1.0, False), _health(i, **health), tr,  # type: ignore[arg-type]
                       est or EstimatorReport())


def test_each_event_string_is_a_line_with_its_report() -> None:
    R = np.eye(4)
    R[:3, :3] = so3_exp(np.array([0.0, math.radians(10.0), 0.0]))
    kf = KeyframeReport(3, KeyframeReason.RELOCALISED, 2, TriangulationReport(40, 30, 1, 5, 4),
                        BAReport(BAStatus.OK, 5, 120, 400, 6, 1.4, 0.6, 3))
    recs = [
        _rec(0, PoseStatus.LOST, (), EstimatorReport(init=_init(TwoViewStatus.LOW_PARALLAX, 0, R)),
             segment=None),
        _rec(1, PoseStatus.LOST, ("init_failed:ambiguous",),
             EstimatorReport(init=_init(TwoViewStatus.AMBIGUOUS, 0)), segment=None),
        _rec(2, events=("init_ok:ref=1",), est=EstimatorReport(init=_init(TwoViewStatus.OK, 1))),
        _rec(3, PoseStatus.LOST, ("direct_prior", "lost:too_few_inliers")),
        _rec(4, events=("relocalised:57",), est=EstimatorReport(keyframe=kf)),
        _rec(5, events=("segment_scale_guess:0.25", "init_ok:ref=3", "brand_new:x")),
        _rec(6, est=EstimatorReport(scale=HeightEstimate(6, PlaneStatus.OK, 0.5, 2.4, 80))),
    ]
    lines = [e for r in recs for e in frame_events(r)]
    assert [(e["frame"], e["type"]) for e in lines] == [
        (0, "init_attempt"), (1, "init_failed"), (2, "init_ok"), (3, "direct_prior"), (3, "lost"),
        (4, "relocalised"), (4, "keyframe"), (5, "segment_scale_guess"), (5, "init_ok"),
        (5, "brand_new"), (6, "scale_reading")]
    a = lines[0]["init"]
    assert a["status"] == "low_parallax" and a["ref_index"] == 0 and "T_cur_ref" not in a
    assert a["rotation_to_ref_deg"] == pytest.approx(10.0, abs=1e-9)
    assert lines[1]["status"] == "ambiguous" and lines[1]["init"]["rotation_to_ref_deg"] is None
    assert lines[2]["ref_frame"] == 1 and lines[2]["init"]["n_points"] == 250
    assert lines[4]["pnp_status"] == "too_few_inliers" and lines[4]["tracking"]["outcome"] == "tracked"
    assert lines[5]["n_matches"] == 57
    k = lines[6]
    assert (k["kf_id"], k["reason"], k["n_retrack_dropped"]) == (3, "relocalised", 2)
    assert k["triangulation"]["n_created"] == 30 and k["ba"]["final_rms_px"] == 0.6
    assert lines[7]["scale_guess"] == 0.25 and lines[8]["ref_frame"] == 3
    assert lines[9]["value"] == "x"
    assert lines[10]["scale"] == 2.4 and lines[10]["status"] == "ok"
    assert all(e["t_s"] == pytest.approx(e["frame"] * 0.1) for e in lines)
    for e in lines:  # strict JSON, one line
        text = event_line(e)
        assert "\n" not in text and json.loads(text) == e


def test_scaled_relative_event_carries_the_pnp_failure_and_the_points() -> None:
    rec = dataclasses.replace(
        _rec(7, events=("scaled_relative",)),
        tracking=TrackingReport(TrackOutcome.SCALED_RELATIVE, 900, 21, 1.0, 0.0, False,
                                "too_few_inliers"))
    (line,) = frame_events(rec)
    assert line["type"] == "scaled_relative" and line["pnp_status"] == "too_few_inliers"
    assert line["tracking"]["outcome"] == "scaled_relative" and line["tracking"]["n_inliers"] == 21


def test_jsonable_values() -> None:
    out = jsonable({"a": float("nan"), "b": np.float32(2.5), "c": np.arange(3), "d": np.zeros((5, 5)),
                    "e": (1, float("inf")), "f": PoseStatus.LOST, "g": np.int64(7)})
    assert out == {"a": None, "b": 2.5, "c": [0, 1, 2], "d": {"shape": [5, 5]}, "e": [1, None],
                   "f": "lost", "g": 7}
    assert isinstance(out["g"], int)


@pytest.mark.parametrize(("flags", "gap", "expect"), [
    ([], 2, []),
    ([0, 0], 2, []),
    ([1, 1, 0, 0, 0, 1], 2, [(0, 1), (5, 5)]),
    ([1, 0, 0, 1], 2, [(0, 3)]),
    ([1, 0, 1, 0, 0, 0, 1], 2, [(0, 2), (6, 6)]),
    ([1, 0, 1], 0, [(0, 0), (2, 2)]),
    ([0, 1, 1, 1], 0, [(1, 3)]),
])
def test_flag_ranges(flags: list[int], gap: int, expect: list[tuple[int, int]]) -> None:
    assert flag_ranges([bool(f) for f in flags], gap) == expect


def test_dropped_ranges_and_their_causes() -> None:
    L, T = PoseStatus.LOST, PoseStatus.TRACKED
    recs = [_rec(0, L, segment=None), _rec(1, L, segment=None, low_par=True),
            _rec(2, T, ("init_ok:ref=0",)), _rec(3, T),
            _rec(4, L, ("lost:too_few_points",), blur=True), _rec(5, L, ev=-1.5), _rec(6, T)]
    d = dropped_events(recs)
    assert [(e["first_frame"], e["last_frame"], e["n_frames"]) for e in d] == [(0, 1, 2), (4, 5, 2)]
    assert d[0]["causes"] == ["before_first_map", "low_parallax"]
    assert d[1]["causes"] == ["blur", "exposure"] and d[1]["events"] == ["lost"]
    ranges = flagged_ranges(recs)
    assert ranges["lost"] == [(0, 1), (4, 5)]
    assert ranges["blur"] == [(4, 4)] and ranges["exposure"] == [(5, 5)]
    assert ranges["low_parallax"] == [(1, 1)] and ranges["saturation"] == []
    skipped = SkippedFrame(7, 7 * 10**8 - 5 * 10**7, "img/7.png", "truncated PNG")
    all_lines = run_events(recs, [skipped])
    # dropped ranges at their first frame, before that frame's events; the skip in time order
    kinds = [(e["type"], e["frame"]) for e in all_lines]
    assert kinds.index(("dropped", 0)) == 0
    assert kinds.index(("dropped", 4)) == kinds.index(("lost", 4)) - 1
    assert kinds[-1] == ("skipped", 7) and all_lines[-1]["file"] == "img/7.png"
