"""Turn per-frame health records into frame ranges with a cause and a concrete recommendation."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

from amrvio.diagnostics.health import FrameHealth


def _ranges(flags: Sequence[bool], max_gap: int = 2) -> list[tuple[int, int]]:
    """Index ranges [i0, i1] of True runs; runs separated by <= max_gap False entries merge."""
    out: list[tuple[int, int]] = []
    for i, f in enumerate(flags):
        if not f:
            continue
        if out and i - out[-1][1] <= max_gap + 1:
            out[-1] = (out[-1][0], i)
        else:
            out.append((i, i))
    return out


def _max(vals: Sequence[float | None]) -> float:
    finite = [v for v in vals if v is not None and math.isfinite(v)]
    return max(finite) if finite else float("nan")


def make_advice(records: Sequence[FrameHealth], smear_bound_px: float = 2.0) -> list[str]:
    """One line per problem range, e.g.
    ``frames 120-131: predicted smear 14 px, cap exposure at 4 ms``."""
    found: list[tuple[int, str]] = []
    recs = list(records)

    def add(flag: Callable[[FrameHealth], bool], text: Callable[[list[FrameHealth]], str]) -> None:
        for i0, i1 in _ranges([flag(r) for r in recs]):
            seg = recs[i0 : i1 + 1]
            found.append((i0, f"frames {seg[0].frame}-{seg[-1].frame}: {text(seg)}"))

    def blur_text(seg: list[FrameHealth]) -> str:
        smear = _max([r.blur.smear_px_pred for r in seg])
        caps = [r.blur.max_exposure_s for r in seg if r.blur.max_exposure_s is not None]
        ratio = min(r.blur.ratio for r in seg)
        if math.isfinite(smear) and caps:
            return (
                f"predicted smear {smear:.0f} px, cap exposure at {min(caps) * 1e3:.1f} ms "
                f"(keeps smear <= {smear_bound_px:g} px at the measured rate)"
            )
        return (
            f"motion blur (sharpness down to {ratio:.2f} of recent sharp frames): shorten the "
            "exposure or slow rotation; skip these frames for tracking and rely on the IMU"
        )

    def expo_text(seg: list[FrameHealth]) -> str:
        ev = max((r.exposure.ev for r in seg if math.isfinite(r.exposure.ev)), key=abs, default=0.0)
        return (
            f"exposure step {ev:+.2f} EV: use affine brightness compensation (gain/offset) or a "
            "photometric calibration; limit the auto-exposure rate"
        )

    def sat_text(seg: list[FrameHealth]) -> str:
        return (
            f"{max(r.exposure.saturated_frac for r in seg) * 100:.0f} % of pixels saturated: lower the "
            "exposure/gain target"
        )

    def par_text(seg: list[FrameHealth]) -> str:
        return (
            f"low parallax (median {_max([r.parallax.px for r in seg]):.1f} px since keyframe): "
            "do not initialise here; add lateral motion or turns, or use a metric cue (IMU, wheels)"
        )

    def exc_text(seg: list[FrameHealth]) -> str:
        return (
            "degenerate IMU excitation (near-constant velocity): scale/gravity not observable; "
            "add a forward-stop-turn manoeuvre before VIO initialisation"
        )

    add(lambda r: r.blur.flag, blur_text)
    add(lambda r: r.exposure.flag, expo_text)
    add(lambda r: r.exposure.saturated_frac > 0.1, sat_text)
    add(lambda r: r.parallax.low_flag, par_text)
    add(lambda r: r.excitation is not None and r.excitation.degenerate, exc_text)
    out = [text for _, text in sorted(found, key=lambda x: x[0])]  # by first frame
    if not out:
        out.append(f"frames {recs[0].frame}-{recs[-1].frame}: no problem found" if recs else "no frames")
    return out
