"""Static figures (matplotlib, Agg canvas; no pyplot state).

plot_eval: the figure of ``amrvio eval --plot``: top view of the aligned estimate and the ground
truth, the ATE over time and, when available, the Sim3 scale of the drift windows.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from amrvio.eval.evaluate import EvalResult

_AXES = ("x", "y", "z")


def top_view_axes(positions_m: np.ndarray) -> tuple[int, int]:
    """The two coordinate axes with the largest spread (drops the "up" axis of the motion:
    z for EuRoC, y for KITTI's camera frame)."""
    p = np.asarray(positions_m, dtype=np.float64).reshape(-1, 3)
    spread = p.max(axis=0) - p.min(axis=0) if p.shape[0] else np.zeros(3)
    drop = int(np.argmin(spread))
    a, b = (i for i in range(3) if i != drop)
    return a, b


def plot_eval(result: EvalResult, out_png: str | Path, title: str = "") -> Path:
    """Write the evaluation figure to ``out_png`` and return its path."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    gt = result.gt_matched
    est = result.est_aligned
    a, b = top_view_axes(gt.positions_m)
    windows = [w for w in result.drift_windows if w.scale is not None]
    nrows = 3 if windows else 2
    fig = Figure(figsize=(7.0, 3.2 * nrows + 1.5))
    FigureCanvasAgg(fig)
    gs = fig.add_gridspec(nrows + 1, 1, height_ratios=[2.2] + [1.0] * nrows)
    ax_top = fig.add_subplot(gs[0:2, 0])
    ax_top.plot(gt.positions_m[:, a], gt.positions_m[:, b], "k-", lw=1.2, label="ground truth")
    ax_top.plot(
        est.positions_m[:, a], est.positions_m[:, b], "-", color="tab:red", lw=1.0,
        label=f"estimate ({result.align.value} aligned)",
    )
    ax_top.plot(gt.positions_m[:1, a], gt.positions_m[:1, b], "ko", ms=4)
    ax_top.set_xlabel(f"{_AXES[a]} [m]")
    ax_top.set_ylabel(f"{_AXES[b]} [m]")
    ax_top.set_aspect("equal", adjustable="datalim")
    ax_top.legend(loc="best", fontsize=8)
    ax_top.grid(True, lw=0.3)
    head = f"ATE rmse {result.ate.rmse:.4f} m"
    if result.scale is not None:
        head += f", Sim3 scale {result.scale:.4f}"
    ax_top.set_title(f"{title}\n{head}" if title else head, fontsize=9)

    t = gt.stamps_s - gt.stamps_s[0]
    ax_err = fig.add_subplot(gs[2, 0])
    ax_err.plot(t, result.ate_errors_m, "-", color="tab:blue", lw=1.0)
    ax_err.axhline(result.ate.rmse, color="tab:blue", ls="--", lw=0.8, label="rmse")
    ax_err.set_xlabel("time [s]")
    ax_err.set_ylabel("ATE [m]")
    ax_err.legend(loc="upper left", fontsize=8)
    ax_err.grid(True, lw=0.3)

    if windows:
        ax_s = fig.add_subplot(gs[3, 0])
        t0 = gt.stamps_s[0]
        for w in windows:
            s = float(w.scale) if w.scale is not None else float("nan")
            ax_s.plot([w.t_start_s - t0, w.t_end_s - t0], [s, s], "-", color="tab:green")
        if result.scale is not None:
            ax_s.axhline(result.scale, color="k", ls="--", lw=0.8, label="whole-path scale")
            ax_s.legend(loc="best", fontsize=8)
        ax_s.set_xlabel("time [s]")
        ax_s.set_ylabel("window Sim3 scale")
        ax_s.grid(True, lw=0.3)
    fig.tight_layout()
    out = Path(out_png)
    fig.savefig(out, dpi=110)
    return out
