"""The built-in example trajectory pair (amrvio/data/example_gt.tum, example_est.tum).

A ground robot drives a figure eight for 60 s (20 Hz ground truth). The "estimate" is what a
monocular VO might output: 10 Hz, stamps off by up to 2 ms, an arbitrary world frame and scale
(Sim3), a scale that drifts by ~0.3 % per metre, small position noise and a slow heading drift.
Regenerate the files (deterministic for a seed) with ``python -m amrvio.eval.example``.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from amrvio.types.lie import SO3, Sim3, matrix_to_quat_wxyz, so3_exp
from amrvio.types.trajectory import Trajectory

DATA_DIR = Path(__file__).resolve().parents[1] / "data"
EXAMPLE_GT = DATA_DIR / "example_gt.tum"
EXAMPLE_EST = DATA_DIR / "example_est.tum"

# Sim3 from the ground-truth world to the estimate's world (a monocular VO's arbitrary frame).
_T_EST_GT = Sim3(SO3.exp([0.05, -0.02, 1.1]), np.array([0.7, -1.3, 0.2]), 0.45)


def _yaw_matrices(yaw: np.ndarray) -> np.ndarray:
    return so3_exp(np.stack([np.zeros_like(yaw), np.zeros_like(yaw), yaw], axis=1))


def make_example_pair(seed: int = 0) -> tuple[Trajectory, Trajectory]:
    """Return ``(est, gt)``; same seed, same numbers."""
    rng = np.random.default_rng(seed)
    rate_hz, duration_s = 20.0, 60.0
    t = np.arange(int(duration_s * rate_hz) + 1) / rate_hz
    w = 2.0 * np.pi / 30.0  # one figure eight every 30 s
    pos = np.stack([4.0 * np.sin(w * t), 2.0 * np.sin(2.0 * w * t), np.full_like(t, 0.3)], axis=1)
    vel = np.stack(
        [4.0 * w * np.cos(w * t), 4.0 * w * np.cos(2.0 * w * t), np.zeros_like(t)], axis=1
    )
    yaw = np.unwrap(np.arctan2(vel[:, 1], vel[:, 0]))
    gt = Trajectory(t, pos, matrix_to_quat_wxyz(_yaw_matrices(yaw)))

    # Estimate: integrate the true steps with a drifting scale, noise and heading drift.
    steps = np.diff(pos, axis=0)
    dist = np.concatenate([[0.0], np.cumsum(np.linalg.norm(steps, axis=1))])
    scale = 1.0 + 0.003 * dist[1:]
    heading_drift = np.cumsum(rng.normal(0.0, 2e-4, t.size))
    Rd = _yaw_matrices(heading_drift)
    p_est = np.zeros_like(pos)
    p_est[0] = pos[0]
    for k in range(1, t.size):
        step = Rd[k] @ (scale[k - 1] * steps[k - 1])
        p_est[k] = p_est[k - 1] + step + rng.normal(0.0, 0.002, 3)
    R_est = Rd @ gt.rotations() @ so3_exp(rng.normal(0.0, 0.003, (t.size, 3)))
    keep = np.arange(0, t.size, 2)
    jitter = rng.uniform(-0.002, 0.002, keep.size)
    est = Trajectory(t[keep] + jitter, p_est[keep], matrix_to_quat_wxyz(R_est[keep]))
    return est.transformed(_T_EST_GT), gt


def write_example(out_dir: Path = DATA_DIR, seed: int = 0) -> tuple[Path, Path]:
    """Write ``example_est.tum`` and ``example_gt.tum`` into ``out_dir``; returns their paths."""
    from amrvio.io.trajectory import write_tum

    est, gt = make_example_pair(seed)
    out_dir.mkdir(parents=True, exist_ok=True)
    est_path, gt_path = out_dir / EXAMPLE_EST.name, out_dir / EXAMPLE_GT.name
    write_tum(est_path, est)
    write_tum(gt_path, gt)
    return est_path, gt_path


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--out", type=Path, default=DATA_DIR, help="output folder")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    write_example(args.out, args.seed)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
