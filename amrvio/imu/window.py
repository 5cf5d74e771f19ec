"""The IMU samples that belong to one camera frame."""

from __future__ import annotations

from amrvio.types.sensors import ImuData

FIRST_FRAME_LOOKBACK_NS = 2_000_000_000
"""Before the first frame, the window reaches this far back (there is no previous frame)."""

MARGIN_NS = 10_000_000
"""Extra time on both ends, so the samples around each end are in the window."""


def frame_imu_window(
    imu: ImuData, t_ns: int, prev_t_ns: int | None, exposure_s: float
) -> ImuData:
    """Samples from the previous frame (or ``FIRST_FRAME_LOOKBACK_NS`` before this one) to the
    middle of this frame's exposure (``t_ns + exposure_s / 2``), widened by ``MARGIN_NS`` at
    both ends; ``t_ns`` is the start of the exposure."""
    t0 = (prev_t_ns if prev_t_ns is not None else t_ns - FIRST_FRAME_LOOKBACK_NS) - MARGIN_NS
    return imu.window(t0, t_ns + int(exposure_s * 0.5e9) + MARGIN_NS)
