"""Linking a new map to the previous one through their shared points: the similarity between
two maps built from one scene at different scales is recovered, outliers are ignored, and too
few shared points give no link (instead of a guess)."""

from __future__ import annotations

import numpy as np

from amrvio.estimator.segment_link import LinkConfig, link_segments
from amrvio.estimator.vo_map import VoMap
from amrvio.types.lie import Sim3, so3_exp


def _maps(n_common: int, n_bad: int, seed: int = 0) -> tuple[VoMap, VoMap, Sim3]:
    rng = np.random.default_rng(seed)
    X = rng.uniform([-5, -2, 4], [5, 2, 20], (200, 3))
    truth = Sim3.from_srt(2.7, so3_exp(np.array([0.1, -0.3, 0.05])), np.array([1.0, -2.0, 0.5]))
    old, new = VoMap(), VoMap()
    old.set_points(np.arange(200), X)  # ids 0-199 in the old map
    ids = np.arange(200 - n_common, 400)  # the last n_common of them are shared
    Y = rng.uniform([-5, -2, 4], [5, 2, 20], (len(ids), 3))
    Y[:n_common] = truth.inverse().act(X[200 - n_common:])
    Y[:n_bad] += rng.normal(0, 3.0, (n_bad, 3))  # tracks that jumped during the loss
    new.set_points(ids, Y)
    return new, old, truth


def test_the_similarity_between_two_maps_is_recovered_despite_outliers() -> None:
    new, old, truth = _maps(40, 12)
    link = link_segments(new, old, LinkConfig(), seed=1)
    assert link.old_from_new is not None and link.n_common == 40 and link.n_inliers == 28
    S = link.old_from_new
    assert abs(S.s / truth.s - 1) < 1e-9
    assert np.allclose(S.R, truth.R, atol=1e-9) and np.allclose(S.t, truth.t, atol=1e-8)


def test_too_few_shared_points_give_no_link() -> None:
    new, old, _ = _maps(8, 0)
    link = link_segments(new, old, LinkConfig(), seed=1)
    assert link.old_from_new is None and link.n_common == 8
    new, old, _ = _maps(20, 14)  # most shared points disagree
    assert link_segments(new, old, LinkConfig(), seed=1).old_from_new is None
