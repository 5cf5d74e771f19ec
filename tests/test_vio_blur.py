"""The VIO stage's blur gate (:mod:`amrvio.pipeline.vio_blur`): the predicted smear gates a frame
above ``max_smear_px`` whatever the blur score said, and while the smoother runs it keeps a frame
the score calls blurred tracked when the smear is small; without a prediction the score decides.
After tracking, a frame above ``max_smear_px`` is bridged unless its exposure was assumed and PnP
posed it."""

from __future__ import annotations

import numpy as np
import pytest

from amrvio.diagnostics.health import BlurHealth, ExposureHealth, FrameHealth, ParallaxHealth
from amrvio.errors import ConfigError
from amrvio.frontend.tracking_types import TrackOutcome
from amrvio.frontend.tracks import TrackSet
from amrvio.pipeline.vio_blur import blur_gate, bridge_after_tracking
from amrvio.pipeline.vio_report import VioStageConfig, vio_input

CFG = VioStageConfig(max_smear_px=8.0, track_smear_px=4.0)


@pytest.mark.parametrize(("image_blurred", "smear_px", "running", "gated", "event"), [
    (False, 9.0, True, True, "smear_gated"),  # the prediction gates what the score let through
    (False, 9.0, False, True, "smear_gated"),  # before the smoother runs too
    (True, 3.0, True, False, "blur_tracked:smear_px=3.0"),  # a small smear is tracked through
    (True, 4.0, True, False, "blur_tracked:smear_px=4.0"),  # at the bound
    (True, 5.0, True, True, None),  # between the bounds, the score decides
    (True, 3.0, False, True, None),  # the smoother not running: no translation in the prediction
    (True, None, True, True, None),  # no prediction
    (False, None, True, False, None),
    (False, 3.0, True, False, None),
])
def test_the_smear_and_the_score_decide_together(image_blurred: bool, smear_px: float | None, running: bool,
                                                  gated: bool, event: str | None) -> None:
    events: list[str] = []
    assert blur_gate(image_blurred, smear_px, running, CFG, events) is gated
    assert events == ([] if event is None else [event])


@pytest.mark.parametrize(("max_px", "track_px"), [(8.0, -1.0), (8.0, 9.0), (0.0, 0.0)])
def test_bad_bounds_are_refused(max_px: float, track_px: float) -> None:
    with pytest.raises(ConfigError, match="track_smear_px"):
        VioStageConfig(max_smear_px=max_px, track_smear_px=track_px)


@pytest.mark.parametrize(("smear_px", "exposure_known", "pnp_posed", "bridged", "event"), [
    (9.0, False, False, True, None),  # above the bound, no PnP pose (a fallback pose): bridged
    (9.0, False, True, False, "smear_tracked:smear_px=9.0"),  # an assumed exposure: PnP's inliers decide
    (30.0, False, True, False, "smear_tracked:smear_px=30.0"),
    (9.0, True, True, True, None),  # a measured exposure: the prediction is the smear, bridged
    (8.0, False, False, False, None),  # at the bound
    (float("nan"), True, False, False, None),  # no prediction
])
def test_after_tracking_a_smeared_frame_is_bridged_unless_an_assumed_exposure_and_pnp_say_otherwise(
        smear_px: float, exposure_known: bool, pnp_posed: bool, bridged: bool, event: str | None) -> None:
    events: list[str] = []
    assert bridge_after_tracking(smear_px, exposure_known, pnp_posed, CFG, events) is bridged
    assert events == ([] if event is None else [event])


def _health(exposure_s: float | None, smear_px: float | None) -> FrameHealth:
    return FrameHealth(t_ns=0, frame=0, blur=BlurHealth(100.0, 1.0, 1.0, False, smear_px),
                       exposure=ExposureHealth(exposure_s, 1.0, 0.0, 0.0, False, "klt", 0.0, 0.0),
                       parallax=ParallaxHealth(1.0, False, 100, "klt", False))


@pytest.mark.parametrize(("outcome", "usable", "pnp_posed"), [
    (TrackOutcome.TRACKED, True, True),
    (TrackOutcome.SCALED_RELATIVE, True, False),
    (TrackOutcome.ROTATION, True, False),
    (TrackOutcome.DIRECT, True, False),
    (TrackOutcome.TRACKED_BLURRED, False, False),
])
def test_the_stage_input_says_whether_pnp_posed_the_frame_and_whether_its_exposure_is_known(
        outcome: TrackOutcome, usable: bool, pnp_posed: bool) -> None:
    for exposure_s, smear in ((None, 9.0), (0.012, 9.0), (0.012, None)):
        inp = vio_input(0, None, outcome, TrackSet(), None, _health(exposure_s, smear))
        assert inp.usable is usable and inp.pnp_posed is pnp_posed
        assert inp.exposure_known is (exposure_s is not None)
        assert inp.smear_px == smear if smear is not None else np.isnan(inp.smear_px)
    inp = vio_input(0, None, outcome, TrackSet(), None, None)  # no diagnostics: no prediction
    assert np.isnan(inp.smear_px)
