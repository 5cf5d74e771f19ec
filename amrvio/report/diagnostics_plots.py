"""Figures of ``amrvio diagnose``: the per-frame health record over time (Agg canvas, no pyplot)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from amrvio.diagnostics.health import FrameHealth


def _col(records: Sequence[FrameHealth], path: str) -> np.ndarray:
    """The values of a dotted field path (e.g. ``"blur.ratio"``) over the records (None: NaN)."""
    out = []
    for r in records:
        v: Any = r
        for name in path.split("."):
            v = getattr(v, name)
        out.append(float("nan") if v is None else float(v))
    return np.asarray(out, dtype=np.float64)


def plot_health(records: Sequence[FrameHealth], out_png: str | Path, title: str = "") -> Path:
    """One PNG with blur, smear, exposure, saturation and parallax over time (flags shaded)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    out = Path(out_png)
    recs = list(records)
    t = np.array([r.t_s for r in recs]) - (recs[0].t_s if recs else 0.0)
    fig = Figure(figsize=(9.0, 11.0))
    FigureCanvasAgg(fig)
    axes = fig.subplots(5, 1, sharex=True)
    panels = [
        ("blur.ratio", "blur ratio", "blur.flag"),
        ("blur.smear_px_pred", "pred. smear [px]", "blur.flag"),
        ("exposure.ev", "exposure change [EV]", "exposure.flag"),
        ("exposure.saturated_frac", "saturated fraction", None),
        ("parallax.px", "parallax [px]", "parallax.low_flag"),
    ]
    for ax, (name, label, flag) in zip(axes, panels, strict=True):
        y = _col(recs, name)
        ax.plot(t, y, lw=1.0)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        if flag is not None:
            f = _col(recs, flag) > 0.5
            finite = y[np.isfinite(y)]
            if f.any() and finite.size:
                lo, hi = float(finite.min()), float(finite.max())
                ax.fill_between(t, lo, hi, where=f, color="tab:red", alpha=0.2, step="mid")
        if not np.isfinite(y).any():
            ax.text(0.5, 0.5, "not available", transform=ax.transAxes, ha="center")
        elif name == "parallax.px":
            top = float(np.nanpercentile(y, 98))
            if top > 0 and float(np.nanmax(y)) > 2.0 * top:  # keep rare outliers from hiding the rest
                ax.set_ylim(0.0, 1.2 * top)
    axes[-1].set_xlabel("time [s]")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(str(out), dpi=90)
    return out


def plot_response_comparison(
    dn: np.ndarray, curves: dict[str, np.ndarray], out_png: str | Path, title: str = ""
) -> Path:
    """Inverse responses (G^-1 normalised to 1 at DN 255) against DN."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(5.0, 4.0))
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    for name, c in curves.items():
        ax.plot(dn, c, label=name)
    ax.set_xlabel("DN")
    ax.set_ylabel("G^-1 (normalised)")
    ax.legend()
    ax.grid(alpha=0.3)
    if title:
        ax.set_title(title)
    fig.tight_layout()
    fig.savefig(str(out_png), dpi=90)
    return Path(out_png)
