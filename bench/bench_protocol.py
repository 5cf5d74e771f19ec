"""Generalisation protocol of the monocular VO, default configuration only: KITTI 00 from several
start frames and with frames dropped, EuRoC MH_01 carried by hand (also every 2nd and every 3rd frame), the
hand-held phone (no ground truth), and the simulator's motion classes.

Per run: frames, the frame of the first initialisation (from the run's start), frames TRACKED
(final status, not interpolated), and the Sim3 ATE as a share of the path. The targets are those
of issue 9; a row states whether it meets them.

Run alone: ``.venv/bin/python -m bench.bench_protocol [--quick]``.
"""

from __future__ import annotations

import dataclasses
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from amrvio.config import PipelineConfig
from amrvio.errors import EvaluationError
from amrvio.eval.evaluate import evaluate
from amrvio.io.base import Dataset
from amrvio.io.dataset import open_dataset
from amrvio.io.trajectory import read_tum
from amrvio.pipeline.pipeline import PipelineOutput
from amrvio.pipeline.records import PoseStatus
from amrvio.pipeline.run import run_pipeline
from amrvio.pipeline.threads import run_settings
from amrvio.types.trajectory import Trajectory

# the protocol measures the monocular VO (issue 9); the simulated recordings carry an IMU, and
# the VIO stage (which has its own bench) would otherwise run and mark its bridged frames
_VO = dataclasses.replace(PipelineConfig(), vio=dataclasses.replace(PipelineConfig().vio, enabled=False))

DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data"
KITTI = DATA / "kitti00_0000-0199"
MH01 = DATA / "euroc_MH_01_handheld_0000-0299"
PHONE = DATA / "phone_handheld_blur_0450-0549"
Row = dict[str, object]


def _subset(ds: Dataset, start: int, n: int | None, step: int) -> Dataset:
    stop = None if n is None else start + n
    return dataclasses.replace(ds, frames=tuple(ds.frames[start:stop:step]))


def _init_frame(out: PipelineOutput) -> int | None:
    for i, r in enumerate(out.records):
        if any(e.startswith("init_ok") for e in r.events):
            return i
    return None


@dataclasses.dataclass(frozen=True, slots=True)
class Targets:
    """Issue 9's targets for one run: the first initialisation within ``max_init`` frames of the
    start, at least ``min_tracked_pct`` of the frames TRACKED (``one_segment``: in the largest
    segment), Sim3 ATE at most ``max_ate_pct`` of the path (None: no ground truth)."""

    max_init: int | None = 10
    min_tracked_pct: float = 97.0
    max_ate_pct: float | None = 1.0
    one_segment: bool = False
    extra: str = ""

    def text(self) -> str:
        parts = [] if self.max_init is None else [f"init <= {self.max_init}"]
        where = " in one segment" if self.one_segment else ""
        parts.append(f">= {self.min_tracked_pct:g} % tracked{where}")
        if self.max_ate_pct is not None:
            parts.append(f"<= {self.max_ate_pct:g} %")
        return ", ".join(parts) + (f", {self.extra}" if self.extra else "")


def _largest_segment(out: PipelineOutput) -> tuple[int | None, int]:
    """The map segment with the most TRACKED frames and that count ((None, 0) without one)."""
    segs = [r.segment for r in out.records if r.status is PoseStatus.TRACKED and r.segment is not None]
    if not segs:
        return None, 0
    big = max(set(segs), key=segs.count)
    return big, segs.count(big)


def _row(name: str, out: PipelineOutput, gt: Trajectory | None, tg: Targets) -> Row:
    n = len(out.records)
    tracked = sum(r.status is PoseStatus.TRACKED for r in out.records)
    in_one = _largest_segment(out)[1]
    n_segs = len({r.segment for r in out.records if r.segment is not None})
    init = _init_frame(out)
    ate_pct = float("nan")
    note = ""
    if gt is not None:
        est = Trajectory.from_matrices(out.stamps_ns * 1e-9, out.T_world_cam)
        try:
            res = evaluate(est, gt, align="sim3")
        except EvaluationError as err:  # e.g. a straight path: Sim3 is undefined
            note = f"no Sim3 ATE: {err}"
        else:
            ate_pct = 100.0 * res.ate.rmse / res.path_length_m
            note = f"ATE {res.ate.rmse:.3f} m over {res.path_length_m:.1f} m"
    share = 100.0 * (in_one if tg.one_segment else tracked) / n
    ok = share >= tg.min_tracked_pct
    if tg.max_init is not None:
        ok = ok and init is not None and init <= tg.max_init
    if tg.max_ate_pct is not None:
        ok = ok and bool(np.isfinite(ate_pct)) and ate_pct <= tg.max_ate_pct
    value = ate_pct if gt is not None else share
    return {"name": f"protocol {name}", "value": value,
            "unit": "% Sim3 ATE / path" if gt is not None else "% frames tracked in one segment",
            "target": tg.text(), "pass": ok,
            "note": f"{n} frames, init at {init}, {tracked}/{n} tracked "
                    f"({100.0 * tracked / n:.1f} %), {n_segs} segment(s), {in_one} tracked in the "
                    f"largest; {note}"}


def _kitti(quick: bool) -> list[Row]:
    if not KITTI.is_dir():
        return []
    ds = open_dataset(f"kitti:{KITTI}")
    gt = ds.groundtruth
    rows: list[Row] = []
    cases: list[tuple[str, int, int | None, int]] = [
        (f"kitti00 start {s} x100", s, 100, 1) for s in (0, 20, 40, 60, 80, 100)]
    cases += [(f"kitti00 start {s} x80 (in the turn)", s, 80, 1) for s in (110, 120)]
    # frames dropped from each possible first frame (every 3rd from frame 2 ended at 1.36 % on
    # 2026-12-04, from frame 0 at 0.61 %)
    cases += [("kitti00 every 2nd frame from 1", 1, None, 2), ("kitti00 every 3rd frame from 1", 1, None, 3),
              ("kitti00 every 3rd frame from 2", 2, None, 3)]
    cases += [("kitti00 every 2nd frame", 0, None, 2), ("kitti00 every 3rd frame", 0, None, 3),
              ("kitti00 0-199", 0, None, 1)]
    if quick:  # the first start, and frames dropped from frame 0 and all frames
        cases = cases[:1] + cases[-3:]
    for name, start, n, step in cases:
        out = run_pipeline(_subset(ds, start, n, step), _VO)
        tg = Targets(max_ate_pct=0.65 if name.endswith("0-199") else 1.0)
        if step > 1:
            tg = Targets(max_init=None, min_tracked_pct=100.0, extra="every frame posed")
        rows.append(_row(name, out, gt, tg))
    return rows


def _mh01() -> list[Row]:
    if not MH01.is_dir():
        return []
    ds = open_dataset(str(MH01))
    gt = read_tum(MH01 / "gt" / "groundtruth_cam0_tum.txt")
    names = {1: "", 2: " every 2nd frame", 3: " every 3rd frame"}
    return [_row(f"euroc MH_01 hand-held{names[step]}", run_pipeline(_subset(ds, 0, None, step), _VO), gt, Targets())
            for step in (1, 2, 3)]


PHONE_TOP_VIEW = Path(__file__).resolve().parent / "results" / "phone_topview.png"


def _keyframe_rms_px(out: PipelineOutput, segment: int | None) -> list[float]:
    """The local BA's final RMS reprojection error (pixels, no robust loss) at each keyframe of
    ``segment``."""
    rms: list[float] = []
    for r in out.records:
        kf = r.estimator.keyframe
        if r.segment == segment and kf is not None and kf.ba is not None and kf.ba.final_rms_px is not None:
            rms.append(float(kf.ba.final_rms_px))
    return rms


def _phone_top_view(out: PipelineOutput, big: int | None, path: Path) -> tuple[float, float]:
    """Write the top view of the phone's camera path, one colour per map segment (each in its
    own, guessed, units), to ``path``; segment ``big``'s largest and median frame-to-frame step
    (its units)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from amrvio.report.plots import top_view_axes

    c = out.T_world_cam[:, :3, 3]
    seg = np.array([-1 if r.segment is None else r.segment for r in out.records])
    a, b = top_view_axes(c[seg == big])
    fig = Figure(figsize=(7.0, 5.0))
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    for k in sorted(set(seg.tolist()) - {-1}):
        m = seg == k
        ax.plot(c[m, a], c[m, b], ".-", lw=1.0, ms=3, label=f"segment {k}: {int(m.sum())} frames")
    ax.plot(c[:1, a], c[:1, b], "ko", ms=4, label="first frame")
    ax.set_xlabel(f"{'xyz'[a]} [map units]")
    ax.set_ylabel(f"{'xyz'[b]} [map units]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    ax.set_title("phone hand-held over a desk: camera path, top view (no ground truth)", fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    step = np.linalg.norm(np.diff(c[seg == big], axis=0), axis=1)
    return float(step.max()), float(np.median(step))


def _phone() -> list[Row]:
    if not PHONE.is_dir():
        return []
    ds = open_dataset(str(PHONE), PHONE / "calib_claimed" / "live.yaml")
    out = run_pipeline(ds, _VO)
    big = _largest_segment(out)[0]
    rms = _keyframe_rms_px(out, big)
    med = float(np.median(rms)) if rms else float("nan")
    top, typical = _phone_top_view(out, big, PHONE_TOP_VIEW)
    return [_row("phone hand-held (no ground truth)", out, None,
                 Targets(max_init=None, min_tracked_pct=90.0, max_ate_pct=None, one_segment=True)),
            {"name": "protocol phone hand-held: median reprojection error, largest segment", "value": med,
             "unit": "px", "target": "<= 1.5 px", "pass": bool(med <= 1.5),
             "note": f"the median over the {len(rms)} keyframes of segment {big} of the local BA's final RMS "
                     "reprojection error over its window (no robust loss, before the outliers are culled), "
                     f"p90 {np.percentile(rms, 90) if rms else float('nan'):.2f} px; top view: "
                     f"{PHONE_TOP_VIEW.relative_to(PHONE_TOP_VIEW.parents[2])}, in that segment the largest "
                     f"frame-to-frame step is {top / typical:.1f} times the median one"}]


# (scene, motion, seconds, --blackout, --seed) of the simulated runs; 752x480 at 20 fps, no blur.
# The black-outs are also rendered with seeds 1 and 2: one draw of a relocalisation is not a
# result (seed 2 of the corridor ended at 5.6 % on 2026-12-04, seeds 0 and 1 at 0.4-0.5 %)
SIM_CASES: tuple[tuple[str, str, float, str, int], ...] = (
    ("corridor", "forward-stop-turn", 8.0, "", 0),
    ("corridor", "constant-velocity", 8.0, "", 0),
    ("warehouse", "rough-floor", 8.0, "", 0),
    ("room", "handheld", 8.0, "", 0),
    ("wall", "wall-scan", 8.0, "", 0),  # one textured plane fills the view: a homography init
    ("room", "start-in-turn", 8.0, "", 0),  # turning at 0.4 rad/s and moving from the first frame
    ("warehouse", "turn-in-place", 8.0, "", 0),  # stops and turns 30 deg in place in 2 s at 2.5 s
    ("corridor", "forward-stop-turn", 10.0, "4.5:1.0", 0),  # 1 s black-out: relocalisation
    ("warehouse", "rough-floor", 10.0, "5.0:1.0", 0),
    ("corridor", "forward-stop-turn", 10.0, "4.5:1.0", 1),
    ("corridor", "forward-stop-turn", 10.0, "4.5:1.0", 2),
    ("warehouse", "rough-floor", 10.0, "5.0:1.0", 1),
    ("warehouse", "rough-floor", 10.0, "5.0:1.0", 2),
)


def _sim(quick: bool) -> list[Row]:
    from amrvio.sim.simulate import SimConfig, simulate

    cases = SIM_CASES[:1] if quick else SIM_CASES
    rows: list[Row] = []
    with tempfile.TemporaryDirectory() as td:
        for k, (scene, motion, seconds, blackout, seed) in enumerate(cases):
            seq = Path(td) / f"{k}_{scene}_{motion}"
            simulate(SimConfig(scene=scene, motion=motion, seconds=seconds, fps=20.0, width=752,
                               height=480, blur=False, blackouts=blackout, seed=seed), seq)
            ds = open_dataset(str(seq))
            if ds.groundtruth is None or ds.T_body_cam is None:
                raise RuntimeError("the simulator wrote no ground truth")
            gt = ds.groundtruth.right_multiplied(ds.T_body_cam)
            name = f"sim {scene} {motion} 752x480 {seconds:g} s"
            tg = Targets(max_init=None, min_tracked_pct=98.0)
            if blackout:
                t0, dur = (float(v) for v in blackout.split(":"))
                name += f" black-out {t0:g}-{t0 + dur:g} s" + (f" render seed {seed}" if seed else "")
                # the black frames themselves are interpolated
                tg = Targets(max_init=None, min_tracked_pct=100.0 * (1 - 1.1 * dur / seconds),
                             max_ate_pct=1.5, one_segment=True, extra="one map after the black-out")
            elif motion == "turn-in-place":
                tg = Targets(max_init=None, min_tracked_pct=98.0, extra="the turn tracked")
            elif motion == "constant-velocity":
                tg = Targets(max_init=None, min_tracked_pct=98.0, max_ate_pct=None,
                             extra="(straight: Sim3 undefined)")
            rows.append(_row(name, run_pipeline(ds, _VO), gt, tg))
    return rows


def _rows(quick: bool) -> Iterator[Row]:
    run_settings()  # as `amrvio run` does
    for part in (lambda: _sim(quick), lambda: _mh01(), lambda: _phone(), lambda: _kitti(quick)):
        yield from part()


def run(quick: bool) -> list[Row]:
    return list(_rows(quick))


if __name__ == "__main__":
    for r in _rows("--quick" in sys.argv):
        v = r["value"]
        print(f"{r['name']:<48} {float(v) if isinstance(v, float) else np.nan:>8.3f} % "
              f"{'PASS' if r['pass'] else 'FAIL'} [{r['target']}] {r['note']}", flush=True)
