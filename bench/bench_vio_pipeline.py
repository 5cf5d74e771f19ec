"""Visual-inertial odometry end to end (issue 10's "done when" figures), each run through
``amrvio.run`` (as ``amrvio run DATASET --out DIR``) on a recording with an IMU:

- simulator replay of the real EuRoC V1_01 flight with its recorded IMU (``amrvio simulate
  --motion replay``, 376x240, the first 30 s): frames posed, SE3 ATE of the body, scale error;
- real EuRoC MH_01 images (hand-held part) with an IMU synthesised from the ground truth at the
  ADIS16448 densities of its calib/imu0_sensor.yaml (amrvio.sim.imu_from_gt): same figures;
- simulator forward-stop-turn (corridor, 376x240, 8 s): the time from the start of the drive until
  the causal metric scale stays within 2 % (scale of the VIO's online positions from the start to
  each frame against the ground truth, rotation about gravity aligned);
- blur bursts (forward-stop-turn with two 0.5 s yaw oscillations of 22 and 33 px of smear): every
  frame posed (IMU bridging), and the ATE against the same run rendered without blur; the
  headline pair, then a protocol of other seeds, burst times and orders (:data:`BURST_CASES`);
- forward-stop-turn runs (no ``--wheels``) also calibrate the simulated wheels
  (``summary.json`` ``wheel_calibration``): the factor's error against the simulated 2 %;
- constant-velocity corridor: the IMU-only initialiser's statuses, and the scale error with the
  wheel odometry (``--wheels``), uncalibrated and with the factor of forward-stop-turn seed 0.

Accuracy: ``eval.json`` of the run (SE3 and Sim3 alignment of the body poses); on a straight path,
where Umeyama's rotation is undefined, the alignment about gravity (``yaw_aligned``).

Run alone: ``.venv/bin/python -m bench.bench_vio_pipeline [--quick]``.
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from amrvio.app.run import RunResult
from amrvio.app.run import run as run_recording
from amrvio.eval.evaluate import evaluate
from amrvio.io.calib import read_euroc_imu
from amrvio.io.dataset import open_dataset
from amrvio.pipeline.records import PoseStatus
from amrvio.pipeline.run_eval import body_groundtruth, yaw_alignment
from amrvio.pipeline.threads import run_settings
from amrvio.sim.imu_from_gt import write_with_synthetic_imu
from amrvio.sim.simulate import SimConfig, simulate
from amrvio.types.trajectory import Trajectory

DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data"
V101 = DATA / "euroc_V1_01_easy_first95" / "mav0"
MH01 = DATA / "euroc_MH_01_handheld_0000-0299"
Row = dict[str, object]
W, H = 376, 240
DRIVE_START_S = 0.5  # forward-stop-turn rests 0.5 s, then drives


def _posed(res: RunResult) -> tuple[int, int, int]:
    recs = res.records
    lost = sum(r.status is PoseStatus.LOST for r in recs)
    bridged = sum(r.status is PoseStatus.BRIDGED for r in recs)
    return len(recs) - lost, len(recs), bridged


def _run(data: Path, out: Path) -> tuple[RunResult, float]:
    t0 = time.perf_counter()
    res = run_recording(str(data), out=out, report=False, force=True)
    return res, time.perf_counter() - t0


def _accuracy_rows(tag: str, res: RunResult, secs: float, ate_max: float, scale_max: float) -> list[Row]:
    posed, n, bridged = _posed(res)
    ev: dict[str, Any] = res.eval_summary or {}
    ate = ev.get("ate_metric_m")
    scale = ev.get("scale_error_pct")
    note = (f"{n} frames, {bridged} bridged; Sim3 ATE {ev.get('ate_sim3_m') or float('nan'):.4f} m of "
            f"{ev.get('path_length_m') or float('nan'):.2f} m; {secs:.0f} s wall; "
            f"{sum(e[1].startswith('vio_reinit') for e in res.summary['events'])} re-inits")
    return [
        {"name": f"{tag}: frames posed", "value": 100.0 * posed / max(n, 1), "unit": "%", "note": note,
         "target": "100 %", "pass": posed == n},
        {"name": f"{tag}: SE3 ATE (body)", "value": float(ate) if ate is not None else float("nan"), "unit": "m",
         "note": note, "target": f"<= {ate_max} m", "pass": ate is not None and ate <= ate_max},
        {"name": f"{tag}: scale error", "value": float(scale) if scale is not None else float("nan"), "unit": "%",
         "note": "Sim3 scale of the body trajectory against the ground truth", "target": f"<= {scale_max} %",
         "pass": scale is not None and scale <= scale_max},
    ]


#: render seeds of the replay protocol (the room's texture and the sensor noise; the flight and
#: its IMU are the recording's) and simulator seeds of the forward-stop-turn protocol; the first
#: of each is the headline run. One run is not a result: on the replay, seed 0 passed the scale
#: target (0.76 %) while seeds 1-3 gave 1.95-3.02 %. The forward-stop-turn runs 10 seeds (8 s
#: each): whether a seed crosses 2 % before or after 3 s turns on excursions of 1.5-3.5 % that small
#: front-end changes move (the gyro-predicted KLT moved seed 0 from 0.825 s to 3.475 s and seed 6
#: from 3.375 s to 0.825 s); 4 seeds could not tell such a change from noise.
REPLAY_SEEDS = (0, 1, 2, 3)
FST_SEEDS = tuple(range(10))
#: seeds of the IMU synthesised for the real MH_01 images (its noise and bias walk)
MH01_SEEDS = (0, 1, 2, 3)


def _seed_rows(tag: str, seeds_name: str, seeds: tuple[int, ...], first: list[Row],
               others: list[dict[str, Any]], ate_max: float, scale_max: float) -> list[Row]:
    """The protocol rows of a case run over ``seeds``: the medians of the SE3 ATE and the scale
    error, against their targets; ``first``: the headline run's :func:`_accuracy_rows` (the
    first seed), ``others``: the evaluation summaries of the other seeds' runs."""
    ates, scales = [float(first[1]["value"])], [float(first[2]["value"])]  # type: ignore[arg-type]
    for ev in others:
        ates.append(float(ev.get("ate_metric_m") or float("nan")))
        scales.append(float(ev.get("scale_error_pct") or float("nan")))
    note = (f"{seeds_name} {list(seeds)}: SE3 ATE {[round(a, 4) for a in ates]} m, scale error "
            f"{[round(x, 2) for x in scales]} %")
    name = f"{tag}, protocol over {len(seeds)} {seeds_name}: median"
    return [
        {"name": f"{name} SE3 ATE", "value": float(np.median(ates)), "unit": "m", "note": note,
         "target": f"<= {ate_max} m", "pass": bool(np.median(ates) <= ate_max)},
        {"name": f"{name} scale error", "value": float(np.median(scales)), "unit": "%", "note": note,
         "target": f"<= {scale_max} %", "pass": bool(np.median(scales) <= scale_max)},
    ]


def _replay_run(work: Path, seconds: float, seed: int) -> tuple[RunResult, float]:
    seq = work / f"replay{seed}"
    simulate(SimConfig(motion="replay", scene="room", seconds=seconds, trajectory=str(
        V101 / "state_groundtruth_estimate0" / "data.csv"), imu_csv=str(V101 / "imu0" / "data.csv"),
        cam_extrinsic=str(V101 / "cam0" / "sensor.yaml"), width=W, height=H, seed=seed), seq, force=True)
    return _run(seq, work / f"replay{seed}_out")


def replay(work: Path, quick: bool) -> list[Row]:
    seconds = 15.0 if quick else 30.0
    tag = f"VIO sim replay V1_01 {seconds:.0f} s 376x240 (recorded IMU)"
    res, secs = _replay_run(work, seconds, REPLAY_SEEDS[0])
    rows = _accuracy_rows(tag, res, secs, 0.05, 1.0)
    if quick:
        return rows
    others = [_replay_run(work, seconds, seed)[0].eval_summary or {} for seed in REPLAY_SEEDS[1:]]
    return rows + _seed_rows(tag, "render seeds", REPLAY_SEEDS, rows, others, 0.05, 1.0)


def _mh01_run(work: Path, seed: int) -> tuple[RunResult, float]:
    seq = work / f"mh01_{seed}"
    noise = read_euroc_imu(MH01 / "calib" / "imu0_sensor.yaml")
    write_with_synthetic_imu(MH01, MH01 / "gt" / "groundtruth_body_tum.txt", seq, noise, seed=seed)
    return _run(seq, work / f"mh01_{seed}_out")


def _after_init(res: RunResult, data: Path) -> tuple[float, float, int]:
    """SE3 ATE (m) and Sim3 scale error (%) of the body trajectory from the visual-inertial
    initialisation on (the smoother's estimates; the frames before it are the VO's, put in its
    world by the initialisation's scale and gravity), and that frame (NaN and -1 without one)."""
    body = res.output.body
    gt, _ = body_groundtruth(open_dataset(str(data)))
    if body is None or gt is None:
        return float("nan"), float("nan"), -1
    k0 = body.init_frame
    t_s = np.array([r.t_ns for r in res.output.records[k0:]]) * 1e-9
    T = body.T_world_body[k0:]
    ok = np.all(np.isfinite(T[:, :3, 3]), axis=1)
    est, ref = Trajectory.from_matrices(t_s[ok], T[ok]), gt.interpolated_at(t_s[ok])
    scale_err = evaluate(est, ref, align="sim3").scale_error_pct
    return evaluate(est, ref, align="se3").ate.rmse, float("nan") if scale_err is None else scale_err, k0


def mh01(work: Path) -> list[Row]:
    """The headline seed's rows and the protocol's medians over the whole run, then the medians
    over the frames from the visual-inertial initialisation on: before it, the frames are the
    VO's (a VO segment that a loss ended keeps the scale the VO guessed for it), after it the
    smoother's, and the whole run's figure mixes the two."""
    tag = "VIO EuRoC MH_01 handheld 300 frames (IMU from GT)"
    runs = [_mh01_run(work, seed) for seed in MH01_SEEDS]
    rows = _accuracy_rows(tag, runs[0][0], runs[0][1], 0.05, 2.0)
    others = [res.eval_summary or {} for res, _ in runs[1:]]
    rows += _seed_rows(tag, "IMU seeds", MH01_SEEDS, rows, others, 0.05, 2.0)
    after = [_after_init(res, work / f"mh01_{seed}") for (res, _), seed in zip(runs, MH01_SEEDS, strict=True)]
    ates, scales = [a for a, _, _ in after], [x for _, x, _ in after]
    note = (f"IMU seeds {list(MH01_SEEDS)}: VIO initialised at frames {[k for _, _, k in after]}; over the "
            f"frames from there on, SE3 ATE {[round(a, 4) for a in ates]} m, Sim3 scale error "
            f"{[round(x, 2) for x in scales]} %")
    name = f"{tag}, protocol over {len(MH01_SEEDS)} IMU seeds, frames from the VIO initialisation on: median"
    return rows + [
        {"name": f"{name} SE3 ATE", "value": float(np.median(ates)), "unit": "m", "note": note,
         "target": "<= 0.05 m", "pass": bool(np.median(ates) <= 0.05)},
        {"name": f"{name} scale error", "value": float(np.median(scales)), "unit": "%", "note": note,
         "target": "<= 2.0 %", "pass": bool(np.median(scales) <= 2.0)},
    ]


def _causal_scale_time(res: RunResult, data: Path) -> tuple[float, float]:
    """(seconds after the drive starts when the causal scale is within 2 % from then on, the
    final causal scale error %)."""
    gt = open_dataset(str(data)).groundtruth
    if gt is None:
        return float("nan"), float("nan")
    rows = [(r.t_ns, r.estimator.vio.estimate.state.T_world_body.t) for r in res.records
            if r.estimator.vio is not None and r.estimator.vio.estimate is not None
            and r.estimator.vio.estimate.state is not None]
    if len(rows) < 10:
        return float("nan"), float("nan")
    t = np.array([x[0] for x in rows], dtype=np.float64) * 1e-9
    p = np.array([x[1] for x in rows])
    g = gt.interpolated_at(t).positions_m
    start = float(gt.stamps_s[0]) + DRIVE_START_S
    errs = np.full(len(t), np.inf)
    for k in range(len(t)):
        if np.linalg.norm(g[k] - g[0]) > 0.2:  # a scale needs some path
            errs[k] = yaw_alignment(p[: k + 1], g[: k + 1])["scale_error_pct"]
    bad = np.flatnonzero(errs > 2.0)
    k_ok = int(bad[-1]) + 1 if bad.size else 0
    if k_ok >= len(t):
        return float("inf"), float(errs[-1])
    return float(t[k_ok] - start), float(errs[-1])


def _fst_run(work: Path, seed: int) -> tuple[RunResult, float, Path]:
    seq = work / f"fst{seed}"
    simulate(SimConfig(motion="forward-stop-turn", seconds=8.0, width=W, height=H, seed=seed), seq, force=True)
    res, secs = _run(seq, work / f"fst{seed}_out")
    return res, secs, seq


def _wheel_factor_error(res: RunResult) -> tuple[float, float]:
    """The wheel calibration of a run without wheels (``summary.json``) and its error (%) against
    the simulated wheels' scale error."""
    cal = res.summary.get("wheel_calibration") or {}
    factor = float(cal.get("factor") or float("nan"))
    return factor, 100.0 * (factor / (1.0 + SimConfig().wheel_scale_error) - 1.0)


def forward_stop_turn(work: Path) -> list[Row]:
    res, secs, seq = _fst_run(work, FST_SEEDS[0])
    after, final = _causal_scale_time(res, seq)
    times, factors = [after], [_wheel_factor_error(res)]
    for s in FST_SEEDS[1:]:
        r, _, q = _fst_run(work, s)
        times.append(_causal_scale_time(r, q)[0])
        factors.append(_wheel_factor_error(r))
    cal_err = [abs(e) for _, e in factors]
    ev: dict[str, Any] = res.eval_summary or {}
    ya = ev.get("yaw_aligned") or {}
    note = (f"causal scale error at the end {final:.2f} %; final trajectory yaw-aligned ATE "
            f"{ya.get('ate_m', float('nan')):.4f} m, scale error {ya.get('scale_error_pct', float('nan')):.2f} %; "
            f"{secs:.0f} s wall")
    posed, n, _ = _posed(res)
    return [
        {"name": "VIO sim forward-stop-turn 8 s: scale within 2 % after the drive starts", "value": after,
         "unit": "s", "note": note, "target": "<= 3 s", "pass": bool(after <= 3.0)},
        {"name": "VIO sim forward-stop-turn 8 s: frames posed", "value": 100.0 * posed / max(n, 1), "unit": "%",
         "note": note, "target": "100 %", "pass": posed == n},
        {"name": f"VIO sim forward-stop-turn 8 s, protocol over {len(FST_SEEDS)} seeds: median time to 2 % scale",
         "value": float(np.median(times)), "unit": "s", "target": "<= 3 s", "pass": bool(np.median(times) <= 3.0),
         "note": f"seeds {list(FST_SEEDS)}: {[round(t, 3) for t in times]} s; "
                 f"{sum(t <= 3.0 for t in times)} of {len(times)} within 3 s"},
        {"name": f"VIO sim forward-stop-turn, wheel calibration over {len(FST_SEEDS)} seeds: median |factor error|",
         "value": float(np.median(cal_err)), "unit": "%",
         "note": f"run without --wheels; summary.json wheel_calibration.factor per seed "
                 f"{[round(f, 4) for f, _ in factors]} against the simulated {1.0 + SimConfig().wheel_scale_error:g}; "
                 f"errors {[round(e, 2) for _, e in factors]} %, largest {max(cal_err):.2f} %"},
    ]


def drawn_bursts(seed: int) -> str:
    """The two bursts of a protocol seed, drawn from it: the first starts 2.0, 2.5 or 3.0 s in,
    the second 5.0, 5.5 or 6.0 s, each 0.5 s at a peak yaw rate of 8, 10 or 12 rad/s."""
    rng = np.random.default_rng(1000 + seed)
    t1 = 2.0 + 0.5 * int(rng.integers(0, 3))
    t2 = 5.0 + 0.5 * int(rng.integers(0, 3))
    w1, w2 = (float(w) for w in rng.choice([8.0, 10.0, 12.0], size=2))
    return f"{t1:.1f}:0.5:{w1:g},{t2:.1f}:0.5:{w2:g}"


# (seed, bursts) of the blur-burst protocol: the headline pair first, then three seeds with burst
# times and orders picked by hand, then eight whose bursts are drawn from the seed
# (:func:`drawn_bursts`); smear = f |omega| T = 0.61 * 376 px * omega * 12 ms: 8 rad/s -> 22 px,
# 10 rad/s -> 28 px, 12 rad/s -> 33 px. Four seeds could not tell a median of 20 % from noise:
# the growth of one seed is the ratio of two ATEs of 5-13 mm, and it ranged from -43 % to +73 %.
BURST_CASES: tuple[tuple[int, str], ...] = (
    (0, "2.5:0.5:8,5.5:0.5:12"),
    (1, "2.0:0.5:10,6.0:0.5:12"),
    (2, "3.0:0.5:10,5.0:0.5:12"),
    (4, "2.5:0.5:12,6.0:0.5:8"),
) + tuple((seed, drawn_bursts(seed)) for seed in (3, 5, 6, 7, 8, 9, 10, 11))


def _burst_pair(work: Path, seed: int, bursts: str) -> tuple[float, float, int, int, int, int]:
    """(ATE with blur, ATE without, frames posed, frames, bridged, gated as blurred) of one
    forward-stop-turn drive with yaw bursts, rendered with and without motion blur."""
    out: dict[bool, RunResult] = {}
    for blur in (True, False):
        seq = work / f"burst{seed}_{'blur' if blur else 'sharp'}"
        simulate(SimConfig(motion="forward-stop-turn", seconds=8.0, blur_bursts=bursts, blur=blur, width=W,
                           height=H, seed=seed), seq, force=True)
        out[blur] = _run(seq, work / f"{seq.name}_out")[0]

    def ate(res: RunResult) -> float:
        ev: dict[str, Any] = res.eval_summary or {}
        ya = ev.get("yaw_aligned") or {}
        return float(ev.get("ate_metric_m") or ya.get("ate_m") or float("nan"))

    posed, n, bridged = _posed(out[True])
    return ate(out[True]), ate(out[False]), posed, n, bridged, sum(r.blurred for r in out[True].records)


def blur_bursts(work: Path) -> list[Row]:
    rows: list[Row] = []
    growths: list[float] = []
    all_posed = True
    for k, (seed, bursts) in enumerate(BURST_CASES):
        a_blur, a_sharp, posed, n, bridged, blurred = _burst_pair(work, seed, bursts)
        growth = 100.0 * (a_blur / a_sharp - 1.0)
        growths.append(growth)
        all_posed = all_posed and posed == n
        note = (f"seed {seed}, bursts {bursts} (t0:s:rad/s); ATE {a_blur:.4f} m with blur, {a_sharp:.4f} m "
                f"without; {posed}/{n} posed, {blurred} frames gated as blurred, {bridged} bridged by the IMU")
        if k == 0:
            rows += [
                {"name": "VIO blur bursts 2 x 0.5 s (22, 33 px): frames posed", "value": 100.0 * posed / max(n, 1),
                 "unit": "%", "note": note, "target": "100 %", "pass": posed == n},
                {"name": "VIO blur bursts: ATE growth over the same run without blur", "value": growth, "unit": "%",
                 "note": note, "target": "<= 20 %", "pass": bool(growth <= 20.0)},
            ]
        else:  # the protocol: details, not headlines
            ok = posed == n and growth <= 20.0
            rows.append({"name": f"VIO blur burst protocol, seed {seed}: ATE growth over the run without blur",
                         "value": growth, "unit": "%",
                         "note": f"{note}; every frame posed and growth <= 20 %: {'yes' if ok else 'no'}"})
    med = float(np.median(growths))
    seeds = [seed for seed, _ in BURST_CASES]
    rows.append({"name": f"VIO blur burst protocol over {len(seeds)} seeds: median ATE growth without blur",
                 "value": med, "unit": "%", "target": "<= 20 %", "pass": bool(all_posed and med <= 20.0),
                 "note": f"seeds {seeds}: {[round(g, 1) for g in growths]} %; {sum(g <= 20.0 for g in growths)} of "
                         f"{len(growths)} within 20 %; every frame posed: {'yes' if all_posed else 'no'}"})
    return rows


def constant_velocity(work: Path) -> list[Row]:
    """The corridor at constant velocity: the IMU alone cannot give the scale (the initialiser
    must say so); with the wheels (``--wheels``) the scale is metric."""
    import dataclasses

    from amrvio.config import PipelineConfig

    seq = work / "cv"
    simulate(SimConfig(motion="constant-velocity", seconds=8.0, width=W, height=H), seq, force=True)
    imu_only, secs_imu = _run(seq, work / "cv_imu")
    statuses = sorted({r.estimator.vio.vi_init.status.value for r in imu_only.records
                       if r.estimator.vio is not None and r.estimator.vio.vi_init is not None})
    # the calibration run: forward-stop-turn seed FST_SEEDS[0], same simulated wheels, without --wheels
    cal_out = work / f"fst{FST_SEEDS[0]}_out"
    fst = _fst_run(work, FST_SEEDS[0])[0] if not (cal_out / "summary.json").is_file() else None
    factor = _wheel_factor_error(fst)[0] if fst is not None else float(
        json.loads((cal_out / "summary.json").read_text())["wheel_calibration"]["factor"])
    rows: list[Row] = []
    for tag, f in (("uncalibrated", 1.0), ("calibrated", factor)):
        cfg = PipelineConfig()  # as `amrvio run --wheels --wheel-factor F`
        cfg = dataclasses.replace(
            cfg, vio=dataclasses.replace(cfg.vio, wheel_sigma_m_s=0.05),
            scale=dataclasses.replace(cfg.scale, wheel=dataclasses.replace(cfg.scale.wheel, enabled=True, factor=f)))
        t0 = time.perf_counter()
        wheels = run_recording(str(seq), cfg, out=work / f"cv_wheels_{tag}", report=False, force=True)
        secs = time.perf_counter() - t0
        ev: dict[str, Any] = wheels.eval_summary or {}
        ya = ev.get("yaw_aligned") or {}
        scale = float(ya.get("scale_error_pct", float("nan")))
        posed, n, _ = _posed(wheels)
        wheel_init = [e[1] for e in wheels.summary["events"] if e[1].startswith("vi_init_wheel")]
        note = (f"IMU-only initialiser statuses {statuses} ({secs_imu:.0f} s); --wheels --wheel-factor {f:.4f}: "
                f"{posed}/{n} posed, yaw-aligned ATE {ya.get('ate_m', float('nan')):.4f} m, first wheel init "
                f"{wheel_init[0] if wheel_init else 'none'}; the simulated wheels read "
                f"{100 * SimConfig().wheel_scale_error:g} % long; {secs:.0f} s")
        if tag == "uncalibrated":
            rows += [
                {"name": "VIO sim constant-velocity 8 s: IMU initialiser reports insufficient_excitation",
                 "value": float("insufficient_excitation" in statuses), "unit": "", "note": note,
                 "target": "reported", "pass": "insufficient_excitation" in statuses and "ok" not in statuses},
                {"name": "VIO sim constant-velocity 8 s with uncalibrated wheels: scale error", "value": scale,
                 "unit": "%", "note": note + "; at constant velocity the wheels' own error is the scale's"},
            ]
        else:
            rows.append({"name": "VIO sim constant-velocity 8 s with wheels calibrated on forward-stop-turn: "
                                 "scale error", "value": scale, "unit": "%", "target": "<= 2 %",
                         "pass": bool(scale <= 2.0), "note": note + f"; factor from forward-stop-turn seed "
                                                                     f"{FST_SEEDS[0]} (a run without --wheels)"})
    return rows


def run_rows(quick: bool) -> list[Row]:
    run_settings()  # as `amrvio run` does
    rows: list[Row] = []
    with tempfile.TemporaryDirectory(prefix="amrvio_bench_vio_") as tmp:
        work = Path(tmp)
        parts = [lambda: forward_stop_turn(work), lambda: blur_bursts(work), lambda: constant_velocity(work)]
        if DATA.is_dir():
            parts = [lambda: replay(work, quick), lambda: mh01(work), *parts]
        for part in parts:
            for r in part():
                rows.append(r)
                print(f"{r['name']:<70} {float(r['value']):>9.4f} {r['unit']:<3} "  # type: ignore[arg-type]
                      f"{'' if 'pass' not in r else 'PASS' if r['pass'] else 'FAIL'} [{r.get('target', '')}] "
                      f"{r['note']}", flush=True)
    return rows


def run(quick: bool) -> list[Row]:
    return run_rows(quick)


if __name__ == "__main__":
    only = [a for a in sys.argv[1:] if not a.startswith("--")]
    if only:  # e.g. `python -m bench.bench_vio_pipeline fst`: one scenario
        run_settings()
        with tempfile.TemporaryDirectory(prefix="amrvio_bench_vio_") as tmp:
            w = Path(tmp)
            table = {"replay": lambda: replay(w, "--quick" in sys.argv), "mh01": lambda: mh01(w),
                     "fst": lambda: forward_stop_turn(w), "blur": lambda: blur_bursts(w),
                     "cv": lambda: constant_velocity(w)}
            for name in only:
                for r in table[name]():
                    print(r, flush=True)
    else:
        run_rows("--quick" in sys.argv)
