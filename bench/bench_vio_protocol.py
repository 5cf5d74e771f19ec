"""The VIO's generalisation protocol on real images: EuRoC MH_01 hand-held (300 frames at 20 Hz)
with an IMU synthesised from its ground truth (as in bench_vio_pipeline), run with the default
configuration at other frame rates (every 2nd and every 3rd image kept, the IMU whole) and from a
later start frame. bench_vio_pipeline has the full sequence; one sequence at one rate is not a
result (the brief's first rule).

Each variant is a copy of the synthesised recording whose ``cam0/data.csv`` lists the kept images
(the images and the IMU are links), run through ``amrvio.run`` as ``amrvio run DIR --out OUT``;
figures from its ``eval.json`` (SE3 ATE and Sim3 scale error of the body poses). Two IMU seeds per
variant; the rows are their medians against issue 10's MH_01 targets.

Run alone: ``.venv/bin/python -m bench.bench_vio_protocol``.
"""

from __future__ import annotations

import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

from amrvio.app.run import run as run_recording
from amrvio.io.calib import read_euroc_imu
from amrvio.pipeline.records import PoseStatus
from amrvio.pipeline.threads import run_settings
from amrvio.sim.imu_from_gt import write_with_synthetic_imu

DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data"
MH01 = DATA / "euroc_MH_01_handheld_0000-0299"
Row = dict[str, object]
#: (name, keep every n-th image, first image kept)
VARIANTS = (("every 2nd frame (10 Hz)", 2, 0), ("every 3rd frame (6.7 Hz)", 3, 0), ("from frame 40", 1, 40))
SEEDS = (0, 1)
ATE_MAX_M, SCALE_MAX_PCT = 0.05, 2.0


def _variant(seq: Path, out: Path, step: int, start: int) -> Path:
    """A copy of the EuRoC-layout recording ``seq`` that keeps every ``step``-th image from index
    ``start`` (images, IMU and ground truth are links)."""
    cam = seq / "mav0" / "cam0"
    (out / "mav0" / "cam0").mkdir(parents=True)
    for sub in (seq / "mav0").iterdir():
        if sub.name != "cam0":
            (out / "mav0" / sub.name).symlink_to(sub.resolve())
    (out / "mav0" / "cam0" / "data").symlink_to((cam / "data").resolve())
    shutil.copy(cam / "sensor.yaml", out / "mav0" / "cam0" / "sensor.yaml")
    lines = (cam / "data.csv").read_text().splitlines()
    header = [ln for ln in lines if ln.startswith("#")]
    rows = [ln for ln in lines if ln.strip() and not ln.startswith("#")]
    (out / "mav0" / "cam0" / "data.csv").write_text("\n".join(header + rows[start::step]) + "\n")
    return out


def run_rows() -> list[Row]:
    run_settings()  # as `amrvio run` does
    rows: list[Row] = []
    if not MH01.is_dir():
        return rows
    noise = read_euroc_imu(MH01 / "calib" / "imu0_sensor.yaml")
    with tempfile.TemporaryDirectory(prefix="amrvio_bench_vio_protocol_") as tmp:
        work = Path(tmp)
        seqs = {}
        for seed in SEEDS:
            seqs[seed] = work / f"mh01_{seed}"
            write_with_synthetic_imu(MH01, MH01 / "gt" / "groundtruth_body_tum.txt", seqs[seed], noise, seed=seed)
        for name, step, start in VARIANTS:
            ates, scales, inits, posed = [], [], [], []
            for seed in SEEDS:
                data = _variant(seqs[seed], work / f"{step}_{start}_{seed}", step, start)
                res = run_recording(str(data), out=work / f"{step}_{start}_{seed}_out", report=False, force=True)
                ev = res.eval_summary or {}
                ates.append(float(ev.get("ate_metric_m") or float("nan")))
                scales.append(float(ev.get("scale_error_pct") or float("nan")))
                body = res.output.body
                inits.append(-1 if body is None else body.init_frame)
                posed.append(f"{sum(r.status is not PoseStatus.LOST for r in res.records)}/{len(res.records)}")
            note = (f"IMU seeds {list(SEEDS)}: SE3 ATE {[round(a, 4) for a in ates]} m, scale error "
                    f"{[round(x, 2) for x in scales]} %, frames posed {posed}, VIO initialised at frames {inits}")
            tag = f"VIO protocol EuRoC MH_01 hand-held {name}, median over {len(SEEDS)} IMU seeds:"
            for what, vals, unit, lim in (("SE3 ATE", ates, "m", ATE_MAX_M),
                                          ("scale error", scales, "%", SCALE_MAX_PCT)):
                med = float(np.median(vals))
                rows.append({"name": f"{tag} {what}", "value": med, "unit": unit, "note": note,
                             "target": f"<= {lim} {unit}", "pass": bool(med <= lim)})
                print(f"{rows[-1]['name']:<90} {med:>9.4f} {unit:<2} {'PASS' if med <= lim else 'FAIL'} {note}",
                      flush=True)
    return rows


def run(quick: bool) -> list[Row]:
    del quick  # six runs of 100-260 frames: no shorter form
    return run_rows()


if __name__ == "__main__":
    run_rows()
    sys.exit(0)
