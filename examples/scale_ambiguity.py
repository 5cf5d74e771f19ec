"""Seed demo 1: monocular two-view geometry recovers translation only up to scale; an IMU-derived
metric displacement fixes it.

Run: ``.venv/bin/python examples/scale_ambiguity.py``. Uses amrvio.geometry.two_view (essential
matrix + recoverPose + triangulation) on a synthetic scene, then scales the unit translation and the
triangulated points by ``s = |dp_imu| / |t_unit|`` (seed section 2-3).
"""

from __future__ import annotations

import numpy as np

from amrvio.geometry.two_view import two_view_init
from amrvio.types.lie import SO3


def run(seed: int = 0) -> dict[str, float]:
    rng = np.random.default_rng(seed)
    K = np.array([[420.0, 0.0, 320.0], [0.0, 420.0, 240.0], [0.0, 0.0, 1.0]])
    n = 200
    X = np.stack([rng.uniform(-2, 2, n), rng.uniform(-1, 1, n), rng.uniform(4, 8, n)], 1)
    R = SO3.exp(np.array([0.0, np.radians(5.0), 0.0])).matrix()
    t_metric = np.array([0.20, 0.0, 0.80])  # camera 2 <- camera 1, metres

    def proj(P: np.ndarray) -> np.ndarray:
        return (P[:, :2] / P[:, 2:3]) * 420.0 + np.array([320.0, 240.0])

    u1 = proj(X) + rng.normal(0, 0.5, (n, 2))
    u2 = proj(X @ R.T + t_metric) + rng.normal(0, 0.5, (n, 2))
    res = two_view_init(u1, u2, K)
    t_unit = res.T_c2_c1[:3, 3]
    # The IMU integrates metric displacement over the same interval (here: truth + 2 cm noise).
    dp_imu = t_metric + rng.normal(0, 0.02, 3)
    scale = float(np.linalg.norm(dp_imu) / np.linalg.norm(t_unit))
    valid = res.point_valid
    depth_err = float(np.median(np.abs(scale * res.points_c1[valid, 2] - X[valid, 2])
                                / X[valid, 2]))
    return {
        "status_ok": float(res.ok),
        "t_unit_norm": float(np.linalg.norm(t_unit)),
        "direction_error_deg": float(np.degrees(np.arccos(np.clip(
            t_unit @ t_metric / np.linalg.norm(t_metric) / np.linalg.norm(t_unit), -1, 1)))),
        "true_norm_m": float(np.linalg.norm(t_metric)),
        "scale_hat": scale,
        "metric_t_error_m": float(np.linalg.norm(scale * t_unit - t_metric)),
        "median_depth_rel_error": depth_err,
    }


def main() -> None:
    r = run()
    print("--- monocular two-view: translation known only up to scale ---")
    print(f"recovered |t| = {r['t_unit_norm']:.3f} (unit by convention), true |t| = "
          f"{r['true_norm_m']:.3f} m, direction error {r['direction_error_deg']:.2f} deg")
    print(f"IMU scale fix: s = {r['scale_hat']:.3f}; metric translation error "
          f"{r['metric_t_error_m'] * 100:.1f} cm; median depth error "
          f"{r['median_depth_rel_error'] * 100:.1f} %")


if __name__ == "__main__":
    main()
