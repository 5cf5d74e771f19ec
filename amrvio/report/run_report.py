"""``report.html`` of ``amrvio run``: one self-contained page (plots embedded as PNG, no external
file, script or style sheet).

Sections: the figures table, the plots (top view against the ground truth when there is one; blur
score and predicted smear; exposure change; parallax; IMU excitation when there is an IMU; tracks
and inliers per frame; scale over time; every time plot with the flagged ranges shaded), the
initialisation report, the events (losses, relocalisations, re-initialisations, dropped ranges),
the advice, and the full configuration used (``amrvio config --check`` reads it back).

Figures are drawn on an Agg canvas (no pyplot state); :data:`PLOTS` names them, in page order,
and each ``<img>`` carries its name in ``data-plot``.
"""

from __future__ import annotations

import base64
import html
import io
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from amrvio.pipeline.events import CAUSES, flagged_ranges
from amrvio.pipeline.records import FrameRecord
from amrvio.pipeline.run_eval import estimate_trajectory
from amrvio.report.plots import top_view_axes

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from amrvio.eval.evaluate import EvalResult
    from amrvio.pipeline.pipeline import PipelineOutput

F64 = np.ndarray

PLOTS: tuple[str, ...] = ("top_view", "blur", "exposure", "parallax", "excitation", "tracks",
                          "scale")
"""Every plot the report can hold, in page order ("excitation" only with IMU data)."""

CAUSE_COLOURS: dict[str, str] = {
    "blur": "tab:red", "exposure": "tab:orange", "saturation": "gold",
    "low_parallax": "tab:purple", "low_excitation": "tab:brown", "lost": "black",
}
MAX_EVENT_ROWS = 300
"""The events table lists at most this many lines (events.jsonl has them all)."""


@dataclass(frozen=True, slots=True, eq=False)
class ReportInput:
    """What the page shows: the run (records, refined poses, scale), its summary, the evaluation
    (``eval_summary`` as in eval.json; ``sim3`` for the top view), advice lines, events lines,
    the configuration as YAML text, and the notes of the set-up."""

    title: str
    output: PipelineOutput
    summary: dict[str, Any]
    advice: Sequence[str]
    events: Sequence[dict[str, Any]]
    config_yaml: str
    eval_summary: dict[str, Any] | None = None
    sim3: EvalResult | None = None
    notes: Sequence[str] = field(default_factory=tuple)


# ------------------------------------------------------------------------------------ plots
def _png(fig: Figure) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=80)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def _figure(rows: int = 1, height: float = 2.6) -> tuple[Figure, list[Axes]]:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10.0, height * rows + 0.4))
    FigureCanvasAgg(fig)
    axes = fig.subplots(rows, 1, sharex=True, squeeze=False)[:, 0]
    return fig, list(axes)


def _shade(ax: Axes, t: F64, ranges: dict[str, list[tuple[int, int]]], legend: bool) -> None:
    """Shade each flagged range (record positions) over its time span, one colour per cause."""
    if not t.size:
        return
    dt = float(np.median(np.diff(t))) if t.size > 1 else 0.05
    for cause in CAUSES:
        for k, (i0, i1) in enumerate(ranges.get(cause, [])):
            ax.axvspan(t[i0] - dt / 2, t[i1] + dt / 2, color=CAUSE_COLOURS[cause],
                       alpha=0.15 if cause != "lost" else 0.25, lw=0,
                       label=cause.replace("_", " ") if legend and k == 0 else None)


def _series(records: Sequence[FrameRecord], path: str) -> F64:
    """The values of a dotted field path of the records (``"diagnostics.blur.smear_px_pred"``);
    NaN where a part on the way was not computed (None)."""
    out = []
    for r in records:
        v: Any = r
        for name in path.split("."):
            v = getattr(v, name) if v is not None else None
        out.append(float("nan") if v is None else float(v))
    return np.asarray(out, dtype=np.float64)


def _finish(fig: Figure, axes: list[Axes], title: str) -> str:
    """Axis label, grids, the title, and one legend for all axes on the right."""
    axes[-1].set_xlabel("time [s]")
    handles: list[Any] = []
    labels: list[str] = []
    for ax in axes:
        ax.grid(alpha=0.3)
        h, lab = ax.get_legend_handles_labels()
        handles += h
        labels += lab
    fig.suptitle(title, fontsize=10)
    right = 0.8 if handles else 1.0
    if handles:
        fig.legend(handles, labels, loc="upper left", bbox_to_anchor=(right, 0.9), fontsize=7,
                   frameon=False)
    fig.tight_layout(rect=(0.0, 0.0, right, 1.0))
    return _png(fig)


def _no_data(ax: Axes, text: str) -> None:
    ax.text(0.5, 0.5, text, transform=ax.transAxes, ha="center", va="center", color="0.4")


def plot_top_view(data: ReportInput) -> str:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.0, 6.0))
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    res = data.sim3
    out = data.output
    if res is not None:
        gt, est = res.gt_matched.positions_m, res.est_aligned.positions_m
        a, b = top_view_axes(gt)
        ax.plot(gt[:, a], gt[:, b], "k-", lw=1.2, label="ground truth (camera)")
        ax.plot(est[:, a], est[:, b], "-", color="tab:red", lw=1.0, label="estimate (Sim3 aligned)")
        ax.plot(gt[:1, a], gt[:1, b], "ko", ms=4)
        title = f"top view: ATE {res.ate.rmse:.3f} m (Sim3) over {res.path_length_m:.1f} m"
    else:
        # the poses of trajectory.tum (with VIO: the body's, gravity-aligned and metric)
        p = estimate_trajectory(out).positions_m
        p = p[np.all(np.isfinite(p), axis=1)]
        a, b = top_view_axes(p)
        if len(p):
            ax.plot(p[:, a], p[:, b], "-", color="tab:red", lw=1.0, label="estimate")
            ax.plot(p[:1, a], p[:1, b], "ko", ms=4, label="start")
        else:
            _no_data(ax, "no posed frame")
        yaw = (data.eval_summary or {}).get("yaw_aligned")
        if isinstance(yaw, dict) and "ate_m" in yaw:
            title = (f"top view: ATE {yaw['ate_m']:.3f} m aligned about gravity (a straight path "
                     "has no Sim3 alignment)")
        else:
            title = "top view (no ground truth)" if data.eval_summary is None else \
                "top view (not aligned to the ground truth)"
    if len(out.map_points) and res is None and out.body is None:
        m = out.map_points
        ax.plot(m[:, a], m[:, b], ",", color="0.6", zorder=0, label="map points")
    names = "xyz"
    ax.set_xlabel(f"{names[a]} [m or map units]")
    ax.set_ylabel(f"{names[b]}")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(alpha=0.3)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="best", fontsize=8)
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    return _png(fig)


def _times(records: Sequence[FrameRecord]) -> F64:
    t = np.array([r.t_ns for r in records], dtype=np.float64) * 1e-9
    return t - t[0] if t.size else t


def plot_blur(data: ReportInput, t: F64, ranges: dict[str, list[tuple[int, int]]]) -> str:
    recs = data.output.records
    fig, (ax,) = _figure()
    _shade(ax, t, ranges, True)
    ax.plot(t, _series(recs, "blur.score"), lw=1.0, color="tab:blue", label="blur score")
    ax.set_ylabel("blur score (Var ΔI / Var I)")
    smear = _series(recs, "diagnostics.blur.smear_px_pred")
    ax2 = ax.twinx()
    if np.isfinite(smear).any():
        ax2.plot(t, smear, lw=1.0, color="tab:green")
        ax2.set_ylabel("predicted smear [px]", color="tab:green")
    else:
        ax2.set_yticks([])
        _no_data(ax2, "no smear prediction (needs an IMU)")
    return _finish(fig, [ax], "blur: sharpness score (blue) and gyro-predicted smear (green)")


def plot_exposure(data: ReportInput, t: F64, ranges: dict[str, list[tuple[int, int]]]) -> str:
    recs = data.output.records
    fig, (ax,) = _figure()
    _shade(ax, t, ranges, True)
    ev = _series(recs, "diagnostics.exposure.ev")
    a = _series(recs, "tracking.brightness_a")
    if np.isfinite(ev).any():
        ax.plot(t, ev, lw=1.0, color="tab:blue", label="EV change (diagnostics)")
    with np.errstate(divide="ignore", invalid="ignore"):
        ev_klt = np.log2(a)
    if np.isfinite(ev_klt).any():
        ax.plot(t, ev_klt, lw=0.8, color="tab:gray", ls="--", label="log2 gain a (tracker)")
    if not (np.isfinite(ev).any() or np.isfinite(ev_klt).any()):
        _no_data(ax, "not computed")
    ax.set_ylabel("exposure change [EV]")
    return _finish(fig, [ax], "exposure change between frames")


def plot_parallax(data: ReportInput, t: F64, ranges: dict[str, list[tuple[int, int]]]) -> str:
    recs = data.output.records
    fig, (ax,) = _figure()
    _shade(ax, t, ranges, True)
    y = _series(recs, "diagnostics.parallax.px")
    if np.isfinite(y).any():
        ax.plot(t, y, lw=1.0, color="tab:blue")
        top = float(np.nanpercentile(y, 98))
        if top > 0 and float(np.nanmax(y)) > 2.0 * top:
            ax.set_ylim(0.0, 1.2 * top)
    else:
        _no_data(ax, "not computed")
    ax.set_ylabel("parallax [px]")
    return _finish(fig, [ax], "rotation-compensated parallax since the parallax reference")


def plot_excitation(data: ReportInput, t: F64, ranges: dict[str, list[tuple[int, int]]]) -> str:
    recs = data.output.records
    fig, (ax1, ax2) = _figure(2, 2.0)
    _shade(ax1, t, ranges, True)
    _shade(ax2, t, ranges, False)
    ax1.plot(t, _series(recs, "diagnostics.excitation.accel_std_m_s2"), lw=1.0, color="tab:blue")
    ax1.set_ylabel("accel std [m/s²]")
    ax2.plot(t, _series(recs, "diagnostics.excitation.gyro_mean_rad_s"), lw=1.0,
             color="tab:green")
    ax2.set_ylabel("mean |gyro| [rad/s]")
    return _finish(fig, [ax1, ax2], "IMU excitation over the last window")


def plot_tracks(data: ReportInput, t: F64, ranges: dict[str, list[tuple[int, int]]]) -> str:
    recs = data.output.records
    fig, (ax,) = _figure()
    _shade(ax, t, ranges, True)
    n = _series(recs, "tracking.n_tracks")
    m = _series(recs, "tracking.n_inliers")
    ax.plot(t, n, lw=1.0, color="tab:blue", label="tracks")
    ax.plot(t, m, lw=1.0, color="tab:green", label="inliers")
    kf = np.array([r.is_keyframe for r in recs], dtype=bool)
    if kf.any():
        ax.plot(t[kf], n[kf], "|", color="k", ms=8, label="keyframe")
    ax.set_ylabel("per frame")
    return _finish(fig, [ax], "tracks and PnP inliers per frame")


def plot_scale(data: ReportInput, t: F64, ranges: dict[str, list[tuple[int, int]]]) -> str:
    """Top: the metric scale applied to the map (camera height) and each keyframe's reading;
    below: the Sim3 scale of the estimate to the ground truth over windows of the path (1: the
    scale is right). Either alone when only it exists."""
    out = data.output
    res = data.sim3
    windows = [w for w in res.drift_windows if w.scale is not None] if res is not None else []
    panels = int(bool(out.height_readings)) + int(bool(windows))
    fig, axes = _figure(max(1, panels), 2.2)
    for k, ax in enumerate(axes):
        _shade(ax, t, ranges, k == 0)
    if not panels:
        _no_data(axes[0], "no scale source and no ground truth: monocular scale is arbitrary")
        axes[0].set_ylabel("scale")
    k = 0
    if out.height_readings:
        ax = axes[k]
        k += 1
        fs = np.asarray(out.frame_scale, dtype=np.float64)
        if fs.size == t.size:
            ax.plot(t, fs, lw=1.2, color="tab:blue", label="scale applied")
        pos = {r.index: i for i, r in enumerate(out.records)}
        hi = [(t[pos[h.frame_index]], h.scale) for h in out.height_readings
              if h.frame_index in pos and math.isfinite(h.scale)]
        if hi:
            ax.plot(*zip(*hi, strict=True), ".", color="tab:orange", ms=4,
                    label="keyframe ground-plane reading")
        ax.set_ylabel("m per map unit")
    if windows and res is not None:
        ax = axes[k]
        t0 = float(out.records[0].t_ns) * 1e-9 if out.records else 0.0
        for j, w in enumerate(windows):
            sw = float(w.scale) if w.scale is not None else math.nan
            ax.plot([w.t_start_s - t0, w.t_end_s - t0], [sw, sw], "-", color="tab:red",
                    lw=2, label="Sim3 scale to ground truth, per window" if j == 0 else None)
        ax.axhline(1.0, color="k", lw=0.8, ls="--")
        ax.set_ylabel("true / estimated")
    return _finish(fig, axes, "scale over time")


def render_plots(data: ReportInput) -> dict[str, str]:
    """Each plot of :data:`PLOTS` that applies, as base64 PNG."""
    recs = data.output.records
    t = _times(recs)
    ranges = flagged_ranges(recs)
    out = {"top_view": plot_top_view(data)}
    if not recs:
        return out
    out["blur"] = plot_blur(data, t, ranges)
    out["exposure"] = plot_exposure(data, t, ranges)
    out["parallax"] = plot_parallax(data, t, ranges)
    if any(r.diagnostics is not None and r.diagnostics.excitation is not None for r in recs):
        out["excitation"] = plot_excitation(data, t, ranges)
    out["tracks"] = plot_tracks(data, t, ranges)
    out["scale"] = plot_scale(data, t, ranges)
    return out


# ------------------------------------------------------------------------------------ page
_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:1.5em auto;max-width:1100px;color:#222}
h1{font-size:1.5em}h2{font-size:1.2em;border-bottom:1px solid #ccc;margin-top:1.6em}
table{border-collapse:collapse;font-size:.9em}td,th{border:1px solid #ccc;padding:3px 8px;text-align:left}
th{background:#f3f3f3}td.n{text-align:right;font-variant-numeric:tabular-nums}
img{max-width:100%;display:block;margin:.6em 0}pre{background:#f6f6f6;padding:.8em;overflow:auto;font-size:.8em}
.warn{color:#a40}.state{font-weight:bold}
"""


def _e(x: object) -> str:
    return html.escape(str(x))


def _fmt(v: Any, nd: int = 3) -> str:
    if v is None:
        return "n/a"
    if isinstance(v, float):
        return f"{v:.{nd}f}" if math.isfinite(v) else "n/a"
    return str(v)


def _table(rows: Sequence[Sequence[Any]], head: Sequence[str] | None = None) -> str:
    parts = ["<table>"]
    if head:
        parts.append("<tr>" + "".join(f"<th>{_e(h)}</th>" for h in head) + "</tr>")
    for row in rows:
        cells = []
        for v in row:
            num = isinstance(v, int | float) and not isinstance(v, bool)
            cells.append(f"<td class='n'>{_e(_fmt(v))}</td>" if num else f"<td>{_e(v)}</td>")
        parts.append("<tr>" + "".join(cells) + "</tr>")
    parts.append("</table>")
    return "\n".join(parts)


def figures_rows(data: ReportInput) -> list[tuple[str, Any]]:
    """The figures table: frames and statuses, keyframes, events, flagged ranges, evaluation."""
    s = data.summary
    n = int(s.get("n_frames", 0))
    counts = s.get("status_counts", {})
    rows: list[tuple[str, Any]] = [
        ("state", s.get("state", "")),
        ("frames processed", n),
        ("frames in trajectory.tum", s.get("n_in_trajectory")),
        ("tracked / bridged by the IMU / interpolated / lost",
         f"{counts.get('tracked', 0)} / {counts.get('bridged', 0)} / "
         f"{counts.get('interpolated', 0)} / {counts.get('lost', 0)}"),
        ("frames with a pose [%]", 100.0 * s.get("n_in_trajectory", 0) / n if n else None),
        ("images skipped (unusable)", s.get("n_skipped", 0)),
        ("keyframes", s.get("n_keyframes")),
        ("map points", s.get("n_map_points")),
    ]
    kinds = [e["type"] for e in data.events]
    for k in ("init_ok", "init_failed", "lost", "relocalised", "segment_scale_guess", "dropped"):
        rows.append((f"events: {k}", kinds.count(k)))
    ranges = flagged_ranges(data.output.records)
    for cause in CAUSES:
        r = ranges[cause]
        rows.append((f"flagged ranges: {cause.replace('_', ' ')}",
                     f"{len(r)} ({sum(b - a + 1 for a, b in r)} frames)"))
    ev = data.eval_summary
    if ev is not None:
        yaw = ev.get("yaw_aligned")
        if ev.get("error"):
            rows.append(("evaluation (Sim3/SE3)", f"not possible: {ev['error']}"))
            if isinstance(yaw, dict):
                rows += [("ATE rmse, aligned about gravity, metric [m]", yaw.get("ate_m")),
                         ("scale error, aligned about gravity [%]", yaw.get("scale_error_pct"))]
        else:
            rows += [("ground-truth path [m]", ev.get("path_length_m")),
                     ("ATE rmse, Sim3 aligned [m]", ev.get("ate_sim3_m")),
                     ("ATE rmse, Sim3 [% of path]", ev.get("ate_sim3_pct_of_path")),
                     ("ATE rmse, metric (SE3) [m]", ev.get("ate_metric_m")),
                     ("scale error [%]", ev.get("scale_error_pct"))]
    return rows


def _init_section(data: ReportInput) -> str:
    ev = [e for e in data.events if e["type"] in ("init_ok", "init_failed", "init_attempt")]
    if not ev:
        return "<p>No initialisation attempt (tracking off, or no frame).</p>"
    ok = [e for e in ev if e["type"] == "init_ok"]
    n_failed = sum(e["type"] == "init_failed" for e in ev)
    statuses: dict[str, int] = {}
    for e in ev:
        st = (e.get("init") or {}).get("status", "")
        statuses[st] = statuses.get(st, 0) + 1
    parts = []
    if ok:
        first = ok[0]
        i = first.get("init") or {}
        parts.append(
            f"<p>First map at frame {_e(first['frame'])} (t = {_fmt(first['t_s'])} s) from reference "
            f"frame {_e(first.get('ref_frame'))}: model {_e(i.get('model'))}, "
            f"{_e(i.get('n_points'))} points, parallax {_fmt(i.get('parallax_deg'), 2)} deg "
            f"(median {_fmt(i.get('median_parallax_deg'), 2)} deg), "
            f"{_e(i.get('n_shared_tracks'))} shared tracks.</p>")
        if len(ok) > 1:
            parts.append(f"<p>{len(ok) - 1} re-initialisation(s) after losses (new map segments) "
                         f"at frames {', '.join(str(e['frame']) for e in ok[1:])}.</p>")
    else:
        parts.append("<p class='warn'>No map was ever built: the run has no tracked pose.</p>")
    parts.append(f"<p>{len(ev)} attempts, {n_failed} that moved the reference frame; outcome of "
                 "the attempts:</p>")
    parts.append(_table(sorted(statuses.items(), key=lambda x: -x[1]), ("two-view status", "attempts")))
    return "\n".join(parts)


def _events_section(data: ReportInput) -> str:
    keep = ("init_ok", "init_failed", "lost", "relocalised", "segment_scale_guess", "dropped",
            "skipped")
    ev = [e for e in data.events if e["type"] in keep]
    if not ev:
        return "<p>No loss, relocalisation, re-initialisation or dropped range.</p>"
    rows = []
    for e in ev[:MAX_EVENT_ROWS]:
        detail = {k: v for k, v in e.items() if k not in ("type", "frame", "t_s", "init",
                                                           "tracking")}
        if e["type"] == "init_ok" and e.get("init"):
            detail["model"] = e["init"].get("model")
        if e["type"] == "init_failed" and e.get("init"):
            detail["ref_frame"] = e["init"].get("ref_index")
        text = ", ".join(f"{k} {v}" for k, v in detail.items())
        rows.append((e["frame"], _fmt(e["t_s"]), e["type"], text))
    more = (f"<p>{len(ev) - MAX_EVENT_ROWS} more in events.jsonl.</p>"
            if len(ev) > MAX_EVENT_ROWS else "")
    return _table(rows, ("frame", "t [s]", "event", "details")) + more


def render_html(data: ReportInput, plots: dict[str, str] | None = None) -> str:
    """The page (see the module docstring)."""
    plots = render_plots(data) if plots is None else plots
    s = data.summary
    state = s.get("state", "")
    state_note = (" <span class='warn'>(interrupted: the figures cover the frames done)</span>"
                  if s.get("interrupted") else "")
    imgs = "\n".join(
        f"<img data-plot='{name}' alt='{name.replace('_', ' ')}' "
        f"src='data:image/png;base64,{plots[name]}'>" for name in PLOTS if name in plots)
    advice = "".join(f"<li>{_e(a)}</li>" for a in data.advice) or "<li>none</li>"
    notes = "".join(f"<li>{_e(n)}</li>" for n in data.notes)
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<meta name="viewport" content="width=device-width,initial-scale=1">
<title>amrvio run: {_e(data.title)}</title>
<style>{_CSS}</style></head>
<body>
<h1>amrvio run: {_e(data.title)}</h1>
<p>State: <span class="state">{_e(state)}</span>{state_note}. Shaded in the time plots: flagged
frame ranges by cause (blur, exposure step, saturation, low parallax, low IMU excitation) and the
frames without a pose (lost).</p>
<h2 id="figures">Figures</h2>
{_table(figures_rows(data), ("figure", "value"))}
<h2 id="plots">Plots</h2>
{imgs}
<h2 id="init">Initialisation</h2>
{_init_section(data)}
<h2 id="events">Events</h2>
{_events_section(data)}
<h2 id="advice">Advice</h2>
<ul>{advice}</ul>
{f'<h2 id="notes">Notes</h2><ul>{notes}</ul>' if notes else ''}
<h2 id="config">Configuration used</h2>
<p>Save as a file and pass it with <code>--config</code> to repeat the run exactly.</p>
<pre>{_e(data.config_yaml)}</pre>
</body></html>
"""


__all__ = ["CAUSE_COLOURS", "MAX_EVENT_ROWS", "PLOTS", "ReportInput", "figures_rows",
           "render_html", "render_plots"]
