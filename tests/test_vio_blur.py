"""The VIO stage's blur gate (:mod:`amrvio.pipeline.vio_blur`): the predicted smear gates a frame
above ``max_smear_px`` whatever the blur score said, and while the smoother runs it keeps a frame
the score calls blurred tracked when the smear is small; without a prediction the score decides."""

from __future__ import annotations

import pytest

from amrvio.errors import ConfigError
from amrvio.pipeline.vio_blur import blur_gate
from amrvio.pipeline.vio_report import VioStageConfig

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
