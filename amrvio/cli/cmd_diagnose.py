"""``amrvio diagnose DATASET --out DIR``: per-frame health record, plots and advice."""

from __future__ import annotations

import argparse
from pathlib import Path

from amrvio.cli.args import MAX_FRAMES, bounded, interval, max_frames_int

NAME = "diagnose"
HELP = "per-frame health (blur, gyro smear, exposure change, parallax, excitation) + advice"


EXPOSURE_MS = (0.0, 1000.0)
SMEAR_PX = (0.0, 1000.0)
EV_STEP = (0.0, 20.0)
GYRO_BIAS_RAD_S = 10.0
PHOTOMETRIC_FRAMES = (2, 1000)
DIAGNOSE_OUTPUTS = ("health.csv", "advice.txt", "health.png", "photometric_estimate")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("dataset", help="dataset spec (euroc:PATH, kitti:PATH, ... or a bare PATH)")
    parser.add_argument("--out", type=Path, required=True,
                        help="output folder: created if missing, checked before any work; a "
                             "non-empty one needs --force")
    parser.add_argument("--force", action="store_true",
                        help="write into a non-empty --out (the files of an earlier diagnose are "
                             "removed first; other files are left alone)")
    parser.add_argument("--calib", type=Path, default=None, metavar="FILE",
                        help="calibration file that overrides the dataset's own")
    parser.add_argument("--config", type=Path, default=None, metavar="FILE.yaml",
                        help="pipeline configuration (its diagnostics section; the options below "
                             "override it)")
    parser.add_argument("--max-frames", type=max_frames_int, default=None, metavar="N",
                        help=f"stop after N frames (N in {interval(1, MAX_FRAMES)})")
    parser.add_argument("--assumed-exposure-ms", type=bounded(*EXPOSURE_MS, lo_open=True),
                        default=None, metavar="MS",
                        help="exposure used for the smear prediction when frames carry none, in "
                             f"{interval(*EXPOSURE_MS, lo_open=True)} (default: half the frame "
                             "period, at most 10 ms)")
    parser.add_argument("--smear-bound-px", type=bounded(*SMEAR_PX, lo_open=True), default=2.0,
                        metavar="PX",
                        help="smear bound of the exposure advice, in "
                             f"{interval(*SMEAR_PX, lo_open=True)} (default 2 px)")
    parser.add_argument("--ev-step", type=bounded(*EV_STEP, lo_open=True), default=0.3,
                        metavar="EV",
                        help="|EV| that flags an exposure step, in "
                             f"{interval(*EV_STEP, lo_open=True)} (default 0.3)")
    parser.add_argument("--gyro-bias", default="auto",
                        help="'auto' (mean gyro of a still first second, if still), 'none', "
                        f"or 'x,y,z' in rad/s (each in [-{GYRO_BIAS_RAD_S:g}, "
                        f"{GYRO_BIAS_RAD_S:g}])")
    parser.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    parser.add_argument("--estimate-photometric", type=bounded(0, PHOTOMETRIC_FRAMES[1],
                                                               integer=True),
                        default=0, metavar="N",
                        help="also estimate response, vignette and exposures from N frames spread "
                        f"over the sequence, N in {interval(*PHOTOMETRIC_FRAMES)} (0: off; writes "
                        "photometric_estimate/)")


def run(args: argparse.Namespace) -> int:
    import dataclasses

    import numpy as np

    from amrvio.cli.interrupt import StopRequest
    from amrvio.config import PipelineConfig, load_config
    from amrvio.errors import ConfigError
    from amrvio.io.dataset import open_dataset
    from amrvio.io.outdir import prepare_output_dir
    from amrvio.pipeline.run import diagnose, replacing, write_advice, write_health

    if args.estimate_photometric == 1:
        raise ConfigError("--estimate-photometric needs at least "
                          f"{PHOTOMETRIC_FRAMES[0]} frames (or 0: off), got 1")
    bias: str | np.ndarray = args.gyro_bias
    if args.gyro_bias not in ("auto", "none"):
        try:
            bias = np.array([float(v) for v in args.gyro_bias.split(",")])
        except ValueError:
            bias = np.zeros(0)
        if bias.shape != (3,) or not np.all(np.abs(bias) <= GYRO_BIAS_RAD_S):
            raise ConfigError(f"--gyro-bias must be auto, none or x,y,z with each in "
                              f"[-{GYRO_BIAS_RAD_S:g}, {GYRO_BIAS_RAD_S:g}] rad/s; got "
                              f"{args.gyro_bias[:60]!r}")
    cfg = load_config(args.config) if args.config is not None else PipelineConfig()
    dc = cfg.diagnostics
    cfg = dataclasses.replace(cfg, diagnostics=dataclasses.replace(
        dc, smear_bound_px=args.smear_bound_px,
        exposure=dataclasses.replace(dc.exposure, ev_step=args.ev_step)))
    out: Path = args.out
    prepare_output_dir(out, args.force, DIAGNOSE_OUTPUTS)
    ds = open_dataset(args.dataset, calib=args.calib)
    if not ds.frames:
        raise ConfigError(f"{args.dataset}: the dataset has no frames")
    with StopRequest() as stop:
        recs, setup = diagnose(ds, cfg, gyro_bias=bias, assumed_ms=args.assumed_exposure_ms,
                               max_frames=args.max_frames, progress=True, stop=stop)
    with replacing(out / "health.csv") as tmp:
        write_health(tmp, recs)
    with replacing(out / "advice.txt") as tmp:
        write_advice(tmp, recs, cfg, setup.notes)
    if stop.requested:
        import sys

        print(f"amrvio diagnose: interrupted after {len(recs)} frames; wrote their rows to "
              f"{out / 'health.csv'}", file=sys.stderr)
        return 130
    records = [r.diagnostics for r in recs if r.diagnostics is not None]
    frames = ds.frames if args.max_frames is None else ds.frames[: args.max_frames]
    if not args.no_plots:
        from amrvio.report.diagnostics_plots import plot_health

        plot_health(records, out / "health.png", title=str(ds.root.name))
    if args.estimate_photometric > 0:
        _estimate_photometric(ds, frames, args.estimate_photometric, out, not args.no_plots)
    n_blur = sum(r.blur.flag for r in records)
    n_expo = sum(r.exposure.flag for r in records)
    n_par = sum(r.parallax.low_flag for r in records)
    print(f"{len(records)} frames: {n_blur} blurred, {n_expo} exposure steps, "
          f"{n_par} low-parallax; wrote {out / 'health.csv'}, {out / 'advice.txt'}")
    return 0


def _estimate_photometric(ds: object, frames: object, n: int, out: Path, plots: bool) -> None:
    """Estimate G, V and exposures from ``n`` frames; compare with the dataset's own files."""
    import numpy as np

    from amrvio.photometric.calibrate import (
        CalibrationStatus,
        estimate_photometric_calibration,
        track_observations,
    )
    from amrvio.photometric.model import PhotometricCalibration, compare_inverse_responses

    seq = list(frames)  # type: ignore[call-overload]
    idx = np.unique(np.linspace(0, len(seq) - 1, min(n, len(seq))).round().astype(int))
    chosen = [seq[i] for i in idx]
    images = [f.load() for f in chosen]
    times = [f.exposure_s for f in chosen]
    known = all(t is not None and t > 0 for t in times)
    obs = track_observations(images)
    est = estimate_photometric_calibration(obs, np.array(times, float) if known else None)
    d = out / "photometric_estimate"
    d.mkdir(parents=True, exist_ok=True)
    lines = [f"frames used: {len(images)}; exposures {'known' if known else 'estimated'}",
             f"status: {est.status.value}; observations {est.n_observations}; "
             f"rms {est.rms_dn:.2f} DN" if np.isfinite(est.rms_dn) else "rms n/a",
             f"response: gamma {est.response.gamma:.4f}, coefficients "
             + " ".join(f"{c:.4f}" for c in est.response.coeffs),
             f"vignette: v1 {est.vignette.v1:.4f} v2 {est.vignette.v2:.4f} v3 {est.vignette.v3:.4f}"]
    if est.status is not CalibrationStatus.TOO_FEW_OBSERVATIONS:
        h, w = images[0].shape
        cal = PhotometricCalibration.from_models(est.response, est.vignette, h, w)
        cal.save(d / "pcalib.txt", d / "vignette.png")
        mine = cal.inverse_response / cal.inverse_response[250]
        ref_lut = getattr(ds, "inverse_response", None)
        if ref_lut is not None:
            ref = np.asarray(ref_lut, float) - float(ref_lut[0])
            ref = ref / ref[250]
            cmp = compare_inverse_responses(cal.inverse_response, ref)
            lines.append(f"inverse response vs the dataset's pcalib.txt: RMS "
                         f"{cmp.rms_scale_aligned * 100:.2f} % after the least-squares scale, "
                         f"{cmp.rms_at_250 * 100:.2f} % with both normalised to 1 at DN 250")
            if plots:
                from amrvio.report.diagnostics_plots import plot_response_comparison

                plot_response_comparison(np.arange(256), {"estimated": mine, "dataset": ref},
                                         d / "response.png", "inverse response")
        ref_v = getattr(ds, "vignette", None)
        if ref_v is not None and cal.vignette is not None and ref_v.shape == cal.vignette.shape:
            rv = np.asarray(ref_v, float) / float(np.max(ref_v))
            rms_v = float(np.sqrt(np.mean((cal.vignette - rv) ** 2)))
            lines.append(f"vignette vs the dataset's vignette.png: RMS {rms_v * 100:.2f} %")
    if not known:
        lines.append("exposures unknown: recovered up to one scale and the response-exponent "
                     "gauge (see amrvio.photometric.calibrate)")
    label = "exposures [s]" if known else "relative exposures t_i/t_0"
    lines.append(f"{label}: " + " ".join(f"{t:.6g}" for t in est.exposures_s))
    (d / "report.txt").write_text("\n".join(lines) + "\n", encoding="utf-8")
