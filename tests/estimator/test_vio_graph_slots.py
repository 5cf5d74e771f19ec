"""The smoother's factor slots (amrvio.estimator.vio_graph): iSAM2 reuses the slot of a removed
factor, and :func:`live_slots` tells a frame's slots that still hold its factors from those
the smoother marginalised or filled again."""

from __future__ import annotations

import gtsam
import numpy as np

from amrvio.estimator.vio_graph import live_slots, make_smoother, sym


def _between(i: int) -> gtsam.BetweenFactorPoint3:
    return gtsam.BetweenFactorPoint3(sym("x", i - 1), sym("x", i), np.ones(3), gtsam.noiseModel.Isotropic.Sigma(3, 1.0))


def test_live_slots_are_those_still_holding_their_factor() -> None:
    sm = make_smoother(3)  # a lag of 2 ordinals
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    graph.add(gtsam.PriorFactorPoint3(sym("x", 0), np.zeros(3), gtsam.noiseModel.Isotropic.Sigma(3, 1.0)))
    values.insert(sym("x", 0), np.zeros(3))
    sm.update(graph, values, {sym("x", 0): 0.0})
    added: list[tuple[int, gtsam.BetweenFactorPoint3]] = []
    for i in range(1, 9):
        f = _between(i)
        graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        graph.add(f)
        values.insert(sym("x", i), np.full(3, float(i)))
        sm.update(graph, values, {sym("x", i): float(i)})
        (slot,) = sm.getISAM2Result().getNewFactorsIndices()
        added.append((int(slot), f))
    slots, factors = [s for s, _ in added], [f for _, f in added]
    live = live_slots(sm, slots, factors)
    # the newest factors are in the window; the older ones were marginalised
    assert live == slots[-2:]
    # their slots were reused: the graph is no longer than the window, and a reused slot
    # holds a newer factor, not the one first put there
    assert sm.getFactors().size() <= 4
    reused = [s for s in slots[:-2] if s in slots[-2:]]
    assert reused
    assert all(s not in live_slots(sm, [s], [f]) for s, f in added[:-2])
