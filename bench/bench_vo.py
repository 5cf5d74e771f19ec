"""Monocular VO benchmark: KITTI 00 frames 0-199 (accuracy vs ORB-SLAM3, fps, per-stage
timing, end-to-end fps with PNG decoding, metric scale from the camera height, and the ATE
sensitivity to nearby settings: +-20 % features, BA window +-2), a 752x480 simulated corridor
with 3 EV steps and 2 blur bursts (accuracy, fps, ablation: photometric compensation off, blur
gating off), and the local-BA back-end choice (GTSAM vs SciPy, same problem).

Run alone: ``.venv/bin/python -m bench.bench_vo [--quick]``.
"""

from __future__ import annotations

import dataclasses
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from amrvio.config import PipelineConfig, without_photometric
from amrvio.eval.evaluate import evaluate
from amrvio.io.dataset import Dataset, open_dataset
from amrvio.pipeline.pipeline import PipelineOutput
from amrvio.pipeline.records import PoseStatus
from amrvio.pipeline.run import run_pipeline
from amrvio.pipeline.run_eval import camera_groundtruth
from amrvio.pipeline.threads import run_settings
from amrvio.types.trajectory import Trajectory

KITTI = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "kitti00_0000-0199"
Row = dict[str, object]


def _row(name: str, value: float, unit: str, note: str) -> Row:
    return {"name": name, "value": float(value), "unit": unit, "note": note}


def _eval(out: PipelineOutput, gt: Trajectory, align: str = "sim3") -> tuple[float, float, float]:
    est = Trajectory.from_matrices(out.stamps_ns * 1e-9, out.T_world_cam)
    r = evaluate(est, gt, align=align)
    return r.ate.rmse, r.path_length_m, float(r.scale if r.scale is not None else np.nan)


def _const(img: NDArray[np.uint8]) -> Callable[[], NDArray[np.uint8]]:
    return lambda: img


def _timed_run(spec: str, cfg: PipelineConfig, repeats: int) -> tuple[PipelineOutput, float]:
    ds = open_dataset(spec)
    # preload images so that fps measures the VO, not PNG decoding
    imgs = {f.index: f.load() for f in ds.frames}
    frames = tuple(dataclasses.replace(f, path=None, loader=_const(imgs[f.index]))
                   for f in ds.frames)
    ds = dataclasses.replace(ds, frames=frames)
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = run_pipeline(ds, cfg)
        times.append(time.perf_counter() - t0)
    if out is None:
        raise ValueError("repeats must be >= 1")
    return out, statistics.median(times)


def _stage_rows(prefix: str, out: PipelineOutput) -> list[Row]:
    n = len(out.records)
    return [_row(f"{prefix} stage {k}", 1000.0 * v / n, "ms/frame", "mean over the sequence")
            for k, v in sorted(out.timings_s.items(), key=lambda kv: -kv[1])]


def _kitti(repeats: int) -> list[Row]:
    if not KITTI.is_dir():
        return [_row("kitti00 skipped", float("nan"), "", f"{KITTI} absent")]
    rows: list[Row] = []
    gt = open_dataset(f"kitti:{KITTI}").groundtruth
    if gt is None:
        raise RuntimeError(f"{KITTI} has no poses.txt")
    out, dt = _timed_run(f"kitti:{KITTI}", PipelineConfig(), repeats)
    ate, length, scale = _eval(out, gt)
    n = len(out.records)
    tracked = sum(f.status is PoseStatus.TRACKED for f in out.records)
    rows += [
        _row("kitti00 0-199 frames with a pose", n, "frames", f"{tracked} tracked; ORB-SLAM3 199"),
        _row("kitti00 0-199 Sim3 ATE", ate, "m", "ORB-SLAM3 mono: 0.93 m"),
        _row("kitti00 0-199 Sim3 ATE / path", 100 * ate / length, "%",
             f"path {length:.1f} m; ORB-SLAM3: 0.65 %"),
        _row("kitti00 0-199 VO throughput", n / dt, "frames/s",
             f"median of {repeats}; images preloaded; ORB-SLAM3: ~34"),
    ]
    rows += _stage_rows("kitti00", out)
    # end to end, as `amrvio run` does it: PNG decoding included
    ds_png = open_dataset(f"kitti:{KITTI}")
    t0 = time.perf_counter()
    run_pipeline(ds_png, PipelineConfig())
    rows.append(_row("kitti00 0-199 VO throughput, PNG decoding included", n /
                     (time.perf_counter() - t0), "frames/s", "1 run; ORB-SLAM3: ~34"))
    base = PipelineConfig()
    cfg_h = dataclasses.replace(base, scale=dataclasses.replace(base.scale, camera_height_m=1.65))
    out_h, _ = _timed_run(f"kitti:{KITTI}", cfg_h, 1)
    ate_h, length, s_h = _eval(out_h, gt)
    ate_se3, _, _ = _eval(out_h, gt, align="se3")
    rows += [
        _row("kitti00 --camera-height 1.65 scale error |1-s|", 100 * abs(1 - s_h), "%",
             "s = Sim3 (Umeyama) scale to GT; goal <= 3 %"),
        _row("kitti00 --camera-height 1.65 SE3 ATE (no scale alignment)", ate_se3, "m", ""),
        _row("kitti00 --camera-height 1.65 Sim3 ATE / path", 100 * ate_h / length, "%", ""),
    ]
    return rows


def _ba_window(cfg: PipelineConfig, delta: int) -> PipelineConfig:
    mp = cfg.mapping
    return dataclasses.replace(cfg, mapping=dataclasses.replace(mp, mapper=dataclasses.replace(
        mp.mapper, ba_window=mp.mapper.ba_window + delta)))


def _kitti_sensitivity(quick: bool) -> list[Row]:
    """Sim3 ATE over nearby settings: the margin to ORB-SLAM3's 0.93 m must not be luck."""
    if not KITTI.is_dir():
        return []
    gt = open_dataset(f"kitti:{KITTI}").groundtruth
    if gt is None:
        raise RuntimeError(f"{KITTI} has no poses.txt")
    base = PipelineConfig()
    settings = {
        "default": base,
        "features -20 %": dataclasses.replace(
            base, tracking=dataclasses.replace(base.tracking, klt=dataclasses.replace(
                base.tracking.klt, detector=dataclasses.replace(
                    base.tracking.klt.detector,
                    max_corners=int(0.8 * base.tracking.klt.max_features))))),
        "features +20 %": dataclasses.replace(
            base, tracking=dataclasses.replace(base.tracking, klt=dataclasses.replace(
                base.tracking.klt, detector=dataclasses.replace(
                    base.tracking.klt.detector,
                    max_corners=int(1.2 * base.tracking.klt.max_features))))),
        "BA window -2": _ba_window(base, -2),
        "BA window +2": _ba_window(base, +2),
    }
    if quick:
        settings = {k: v for k, v in settings.items() if k in ("default", "features -20 %")}
    rows: list[Row] = []
    ates = []
    for name, cfg in settings.items():
        out, _ = _timed_run(f"kitti:{KITTI}", cfg, 1)
        ate, _, _ = _eval(out, gt)
        ates.append(ate)
        rows.append(_row(f"kitti00 sensitivity [{name}] Sim3 ATE", ate, "m",
                         f"{len(out.keyframe_indices)} keyframes"))
    rows += [
        _row("kitti00 sensitivity median Sim3 ATE", statistics.median(ates), "m",
             f"over {len(ates)} settings: {', '.join(settings)}; ORB-SLAM3 0.93 m"),
        _row("kitti00 sensitivity max Sim3 ATE", max(ates), "m", "same settings"),
    ]
    return rows


def _sim_sequence(tmp: Path, motion: str, seconds: float, seed: int = 0) -> Path:
    from amrvio.sim.simulate import SimConfig, simulate

    out = tmp / f"{motion}_{seed}"
    t = seconds
    cfg = SimConfig(scene="corridor", motion=motion, seconds=t, fps=20.0, width=752, height=480,
                    ev_steps=f"{0.2 * t:.2f}:+1,{0.45 * t:.2f}:-1.5,{0.7 * t:.2f}:+1",
                    blur_bursts=f"{0.3 * t:.2f}:0.5:3,{0.6 * t:.2f}:0.5:3", seed=seed)
    simulate(cfg, out)
    return out


def _camera_gt(ds: Dataset) -> Trajectory:
    """The simulated sequence's ground-truth camera poses (an error when it has none)."""
    gt, why = camera_groundtruth(ds)
    if gt is None:
        raise RuntimeError(f"the simulator wrote no usable ground truth: {why}")
    return gt


#: render seeds of the corridor's protocol (texture, sensor and IMU noise; the drive is the same):
#: one draw is not a result (seed 0 went from 0.18 to 0.44 % with vio.imu_noise_scale 3, while
#: seeds 0-3 went from a median of 0.50 % to 0.30 %)
CORRIDOR_SEEDS: tuple[int, ...] = (0, 1, 2, 3)


def _corridor_protocol(first: float, seconds: float) -> list[Row]:
    """The full pipeline on the forward-stop-turn corridor over :data:`CORRIDOR_SEEDS`;
    ``first``: seed 0's Sim3 ATE / path (%), already run."""
    pcts = [first]
    with tempfile.TemporaryDirectory() as td:
        for seed in CORRIDOR_SEEDS[1:]:
            ds = open_dataset(str(_sim_sequence(Path(td), "forward-stop-turn", seconds, seed)))
            ate, length, _ = _eval(run_pipeline(ds, PipelineConfig()), _camera_gt(ds))
            pcts.append(100 * ate / length)
    return [_row(f"sim corridor forward-stop-turn 752x480 [full], protocol over {len(CORRIDOR_SEEDS)} render "
                 "seeds: median Sim3 ATE / path", statistics.median(pcts), "%",
                 f"render seeds {list(CORRIDOR_SEEDS)}: {[round(v, 3) for v in pcts]} %; goal <= 0.5")]


def _sim(repeats: int, seconds: float) -> list[Row]:
    rows: list[Row] = []
    base = PipelineConfig()
    variants = {
        "full": base,
        "photometric compensation off": without_photometric(base),
        "blur gating off": dataclasses.replace(base, blur_gating=False),
    }
    with tempfile.TemporaryDirectory() as td:
        for motion in ("forward-stop-turn", "constant-velocity"):
            seq = _sim_sequence(Path(td), motion, seconds)
            ds = open_dataset(str(seq))
            gt_cam = _camera_gt(ds)
            tag = f"sim corridor {motion} 752x480"
            for name, cfg in variants.items():
                if motion != "forward-stop-turn" and name != "full":
                    continue
                out, dt = _timed_run(str(seq), cfg, repeats if name == "full" else 1)
                ate, length, _ = _eval(out, gt_cam)
                n = len(out.records)
                lost_events = sum(1 for r in out.records for e in r.events if e.startswith("lost"))
                fallbacks = sum(1 for r in out.records for e in r.events if e == "direct_fallback")
                not_tracked = sum(f.status is not PoseStatus.TRACKED for f in out.records)
                rows += [
                    _row(f"{tag} [{name}] Sim3 ATE / path", 100 * ate / length, "%",
                         f"{n} frames, path {length:.2f} m, 3 EV steps, 2 blur bursts; "
                         "goal <= 0.5"),
                    _row(f"{tag} [{name}] tracking losses", lost_events, "events",
                         f"{not_tracked} frames interpolated or lost; "
                         f"{fallbacks} direct fallbacks"),
                ]
                if name == "full":
                    rows.append(_row(f"{tag} VO throughput", n / dt, "frames/s",
                                     f"median of {repeats}; images preloaded"))
                    if motion == "forward-stop-turn":
                        rows += _stage_rows("sim 752x480", out)
                        rows += _corridor_protocol(100 * ate / length, seconds)
    return rows


def _ba_backends(repeats: int) -> list[Row]:
    from amrvio.estimator.local_ba import BAProblem, solve_ba_gtsam, solve_ba_scipy
    from amrvio.geometry.projection import project
    from amrvio.types.lie import SE3

    def se3_exp(xi: NDArray[np.float64]) -> NDArray[np.float64]:
        return SE3.exp(xi).matrix()

    rng = np.random.default_rng(0)
    K = np.array([[718.856, 0, 607.19], [0, 718.856, 185.2], [0, 0, 1]])
    nk = 8
    T = np.stack([np.linalg.inv(se3_exp(np.r_[0, 0, 1.0 * i, 0, 0.01 * i, 0])) for i in range(nk)])
    X = rng.uniform([-10, -3, 8], [10, 3, 40], (1000, 3))
    oc, op, ou = [], [], []
    for i in range(nk):
        uv, z = project(K, T[i], X)
        ok = (z > 0) & (uv[:, 0] > 0) & (uv[:, 0] < 1241) & (uv[:, 1] > 0) & (uv[:, 1] < 376)
        idx = np.flatnonzero(ok)
        oc += [i] * len(idx)
        op += list(idx)
        ou.append(uv[idx] + rng.normal(0, 0.5, (len(idx), 2)))
    ocs, ops, ous = np.array(oc), np.array(op), np.vstack(ou)
    cnt = np.bincount(ops, minlength=len(X))
    keep = cnt >= 2
    remap = np.cumsum(keep) - 1
    sel = keep[ops]
    Tn = T.copy()
    for i in range(2, nk):
        Tn[i] = se3_exp(rng.normal(0, 0.02, 6)) @ T[i]
    Xk = X[keep] + rng.normal(0, 0.2, (int(keep.sum()), 3))
    fixed = np.zeros(nk, dtype=bool)
    fixed[:2] = True
    prob = BAProblem(Tn, fixed, Xk, ocs[sel].astype(np.int64), remap[ops[sel]].astype(np.int64),
                     ous[sel], K, 2.0)
    rows: list[Row] = []
    for name, fn, iters in (("gtsam LM SEQUENTIAL_CHOLESKY", solve_ba_gtsam, 10),
                            ("scipy least_squares trf+lsmr", solve_ba_scipy, 10),
                            ("scipy least_squares trf+lsmr", solve_ba_scipy, 50)):
        times, res = [], None
        for _ in range(repeats):
            t0 = time.perf_counter()
            res = fn(prob, iters)
            times.append(time.perf_counter() - t0)
        if res is None:
            raise ValueError("repeats must be >= 1")
        note = (f"{nk} keyframes, {len(Xk)} points, {int(sel.sum())} observations; final "
                f"median reprojection {np.median(res.residual_px):.2f} px (noise 0.5 px)")
        rows.append(_row(f"local BA {name}, {iters} iterations max",
                         1000 * statistics.median(times), "ms", note))
    return rows


def run(quick: bool) -> list[Row]:
    run_settings()  # as `amrvio run` does
    repeats = 1 if quick else 3
    rows = _ba_backends(repeats)
    rows += _kitti(repeats)
    rows += _kitti_sensitivity(quick)
    rows += _sim(repeats, 10.0)
    return rows


if __name__ == "__main__":
    for r in run("--quick" in sys.argv):
        print(f"{r['name']:<70} {r['value']:>10.3f} {r['unit']:<10} {r['note']}")
