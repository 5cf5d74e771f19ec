"""Give back to iSAM2 the relinearisation that its marginalisation takes away.

GTSAM's ``ISAM2::marginalizeLeaves``, which the ``IncrementalFixedLagSmoother`` calls for every
variable that leaves the window, replaces the factors of the marginalised variables by their
marginal on the remaining ones: a ``LinearContainerFactor`` without a linearisation point, whose
keys it adds to ``fixedVariables_``, which relinearisation then skips for good. In our window that
fixes nearly every state: the frame dropped in each update (not a keyframe) ties the newest state
to the last keyframe, so the newest state is fixed at its IMU prediction the moment it enters, and
a keyframe leaves with the landmarks it saw first, whose other views fix every keyframe that saw
them. After a blur burst the estimates then move up to 34 cm and 0.35 m/s from the points where
their factors stay linearised, and the window's scale collapsed on some runs (on the
forward-stop-turn yaw-burst protocol, 4 of 32 runs ended 6-41 cm off).

:func:`fixed_due` tells when a fixed variable has moved far from its linearisation point: a
component of its delta beyond :data:`REBUILD_THRESHOLD`; :func:`rebuild` then starts a new
smoother from the window's factors, at the current estimate: each marginal becomes a
``LinearContainerFactor`` that carries its linearisation point (so that it is evaluated correctly
wherever its variables go), every other factor is linearised anew, and no variable is fixed. The
window's factors, variables and their smoother times are the same before and after.

Why a threshold ten times iSAM2's own (0.01): holding the marginals' variables at one point is what
first-estimates Jacobians do for consistency (Huang et al. 2009: a variable linearised at one point
in every factor, so that the marginal adds no information along what the window cannot observe),
and rebuilding often loses it, at a measured cost in scale. Rebuilding whenever iSAM2 would
relinearise a free variable (73 times in bench_vio_pipeline's 30 s replay of V1_01) took the
replay's scale error from 0.06 to 1.19 %; at 0.05, 3-6 rebuilds, the four render seeds' errors are
0.24 / 0.40 / 0.92 / 0.87 % against 0.06 / 0.66 / 0.05 / 0.11 % without; at 0.1, one rebuild each,
0.13 / 0.71 / 0.17 / 0.08 %. The divergences are caught at 0.1 as at 0.01: over the forward-stop-
turn yaw-burst protocol (bench_vio_pipeline's 4 burst cases and 12 more, each with and without
blur: 32 runs) none ends over 14 mm at 0.1 (median 6.9 mm) nor over 12 mm at 0.01 (6.9 mm); without
rebuilding, 4 ended 6-41 cm off (median 7.4 mm).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from amrvio.estimator.vio_graph import smoother_update

#: a fixed variable whose delta has a component beyond this (rad, m, m/s, bias units) is rebuilt
REBUILD_THRESHOLD = 0.1

if TYPE_CHECKING:
    import gtsam


def fixed_due(smoother: gtsam.IncrementalFixedLagSmoother, threshold: float) -> bool:
    """Whether a variable that iSAM2 holds fixed has a component of its delta (its estimate less
    its linearisation point, in the tangent space) beyond ``threshold``."""
    isam = smoother.getISAM2()
    fixed = list(isam.getFixedVariables())
    if not fixed:
        return False
    delta = isam.getDelta()
    return any(delta.exists(k) and float(np.max(np.abs(delta.at(k)))) > threshold for k in fixed)


def rebuild(smoother: gtsam.IncrementalFixedLagSmoother, params: gtsam.ISAM2Params,
            tick: int) -> tuple[gtsam.IncrementalFixedLagSmoother, dict[int, int]]:
    """A new smoother (lag and ``params`` as given) holding ``smoother``'s factors, variables and
    smoother times, linearised at its current estimate, with no variable fixed; and the slot of
    each factor in it by its slot in ``smoother``. ``tick``: the update's number, as
    :func:`amrvio.estimator.vio_graph.smoother_update` takes it (its ordering constraints keep
    the newest frame's covariance cheap)."""
    import gtsam

    lin = smoother.getLinearizationPoint()
    old = smoother.getFactors()
    graph = gtsam.NonlinearFactorGraph()
    order: list[int] = []
    for slot in range(old.size()):
        if not old.exists(slot):
            continue
        f = old.at(slot)
        if isinstance(f, gtsam.LinearContainerFactor):
            # expressed at iSAM2's linearisation point: the point a marginal without one was made
            # at (its keys were fixed since), or the shift of one that carries its own; the new
            # factor keeps the values of its own keys only
            f = gtsam.LinearContainerFactor(f.linearize(lin), lin)
        order.append(slot)
        graph.add(f)
    stamps = {int(k): float(t) for k, t in smoother.timestamps().items()}
    fresh = gtsam.IncrementalFixedLagSmoother(smoother.smootherLag(), params)
    new_slots = smoother_update(fresh, graph, smoother.calculateEstimate(), stamps, [], tick)
    return fresh, dict(zip(order, new_slots, strict=False))  # the last slot: the prior of z


__all__ = ["REBUILD_THRESHOLD", "fixed_due", "rebuild"]
