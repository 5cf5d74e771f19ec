"""``amrvio info DATASET``: what a recording holds, as a first check before running anything on it."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

NAME = "info"
HELP = "describe a dataset: frames, time span, rates, camera, IMU, noise, T_body_cam, ground truth"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "dataset",
        help="euroc:PATH, tumvi:PATH, tum-mono:PATH, kitti:PATH, bag:PATH, folder:PATH or a bare "
        "PATH (format detected)",
    )
    parser.add_argument("--calib", type=Path, default=None, metavar="FILE",
                        help="calibration file that overrides the dataset's own")
    parser.add_argument("--image-topic", default=None, help="bag image topic (default: the only one)")
    parser.add_argument("--imu-topic", default=None, help="bag IMU topic (default: the only one)")
    parser.add_argument("--check-images", action="store_true",
                        help="decode every image as `run` does and list the ones it would "
                             "skip (unreadable, truncated, another size); exit 1 if any")
    parser.add_argument("--json", type=Path, default=None, metavar="OUT", help="write the summary")


def _num(v: float | None, fmt: str) -> str:
    return "n/a" if v is None else format(v, fmt)


def format_summary(s: dict[str, Any]) -> str:
    """The text printed by ``amrvio info`` (from :func:`amrvio.io.info.dataset_summary`)."""
    fr = s["frames"]
    rows: list[tuple[str, str]] = [("kind", s["kind"]), ("root", s["root"])]
    rows.append(("frames", f"{fr['count']} at {_num(fr['rate_hz'], '.3f')} Hz, "
                           f"{_num(fr.get('duration_s'), '.3f')} s"))
    if fr["count"]:
        rows.append(("time span [ns]", f"{fr['first_t_ns']} .. {fr['last_t_ns']}"))
        rows.append(("image size", f"{fr['width']}x{fr['height']}"))
    cam = s["camera"]
    if cam is None:
        rows.append(("camera", "none (give --calib FILE)"))
    else:
        dist = " ".join(f"{d:.6g}" for d in cam["distortion"]) or "-"
        rows.append(("camera", f"{cam['class']} ({cam['distortion_model']}) {cam['width']}x{cam['height']}"))
        rows.append(("intrinsics fx fy cx cy",
                     f"{cam['fx']:.6g} {cam['fy']:.6g} {cam['cx']:.6g} {cam['cy']:.6g}"))
        rows.append(("distortion", dist))
    T = s["T_body_cam"]
    if T is None:
        rows.append(("T_body_cam", "none"))
    else:
        t = " ".join(f"{v:.6g}" for v in T["t_m"])
        q = " ".join(f"{v:.6g}" for v in T["quat_wxyz"])
        rows.append(("T_body_cam", f"t [m] {t}; q wxyz {q} ({T['angle_deg']:.3f} deg)"))
    imu = s["imu"]
    rows.append(("IMU", "none" if imu is None else
                 f"{imu['samples']} samples at {_num(imu['rate_hz'], '.3f')} Hz, "
                 f"{imu['duration_s']:.3f} s"))
    noise = s["imu_noise"]
    if noise is not None:
        rows.append(("IMU noise (gyro nd, rw; accel nd, rw)",
                     f"{noise['gyro_noise_density']:.6g}, {noise['gyro_random_walk']:.6g}; "
                     f"{noise['accel_noise_density']:.6g}, {noise['accel_random_walk']:.6g}"))
    gt = s["groundtruth"]
    rows.append(("ground truth", "none" if gt is None else
                 f"{gt['poses']} poses (T_world_{gt['frame']}), path {gt['path_length_m']:.3f} m"))
    ex = s["exposure"]
    rows.append(("exposure times", "none" if not ex["frames_with"] else
                 f"{ex['frames_with']} frames, {1e3 * ex['min_s']:.3f} .. {1e3 * ex['max_s']:.3f} ms"))
    ph = s["photometric"]
    present = [k for k in ("inverse_response", "vignette") if ph[k]]
    rows.append(("photometric files", ", ".join(present) if present else "none"))
    bad: list[dict[str, Any]] = s.get("images_unusable", [])
    if "images_checked" in s and not bad:
        rows.append(("images checked", f"{s['images_checked']} decoded, all {fr['width']}x{fr['height']}"))
    elif "images_checked" in s:
        rows.append(("images checked", f"{s['images_checked'] - len(bad)} of {s['images_checked']}"
                                       f" usable; {len(bad)} unusable (amrvio run skips them):"))
    width = max(len(k) for k, _ in rows)
    lines = [f"{k:<{width}}  {v}" for k, v in rows]
    lines += [f"  frame {b['index']}: {b['file']}: {b['problem']}" for b in bad]
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from amrvio.cli.args import check_output_file, write_json
    from amrvio.errors import DatasetFormatError
    from amrvio.io.dataset import open_dataset
    from amrvio.io.info import check_images, dataset_summary

    check_output_file(args.json, "--json")
    ds = open_dataset(args.dataset, args.calib, image_topic=args.image_topic, imu_topic=args.imu_topic)
    summary = dataset_summary(ds)
    if args.check_images:
        from tqdm import tqdm

        with tqdm(total=len(ds.frames), desc="images", unit="frame", file=sys.stderr,
                  disable=not sys.stderr.isatty()) as bar:
            checked = check_images(ds, lambda _k: bar.update(1))
        summary["images_checked"] = checked.n_checked
        summary["images_unusable"] = [
            {"index": b.index, "t_ns": b.t_ns, "file": b.file, "problem": b.problem}
            for b in checked.skipped]
    print(format_summary(summary))
    if args.json is not None:
        write_json(args.json, summary)
    if args.check_images and checked.skipped:
        first = checked.skipped[0]
        raise DatasetFormatError(first.file, f"{first.problem} ({len(checked.skipped)} of "
                                             f"{checked.n_checked} images unusable; listed above)")
    return 0
