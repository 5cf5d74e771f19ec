"""Where the VIO's speed deficit while accelerating comes from (issue 10, forward-stop-turn).

A diagnostic, not part of ``make bench`` (its name does not start with ``bench_``). It renders the
simulator's forward-stop-turn drive (corridor, 376x240, 20 Hz, seed 0 unless given), runs
``amrvio.run`` on it in several variants and prints, for each, the mean ratio of the VIO's online
speed to the true speed while the robot accelerates and decelerates (1.0-3.0 s) and the time
after the drive starts from which the causal scale stays within 2 % (bench_vio_pipeline's figure):

- ``tracks``: the pipeline as it is (the KLT tracks go to the smoother);
- ``true+0.3px``: each observation the smoother gets is replaced by the true projection of its
  track's 3-D point (from the rendered depth at the track's first observation and the true
  camera poses) plus 0.3 px of Gaussian noise; tracks that start on a depth edge are left out;
- ``true+0.01px``: the same with almost no noise;
- ``tracks>1px out``: the KLT tracks, less every observation more than 1 px from its true
  projection (an oracle outlier rejection);

each at the default window (10 keyframes) and at 40. Swapping the observations patches
``VioBackend.add_frame`` and ``VioBackend.initialise`` for the duration of one run (a harness
for this diagnostic only).

Run: ``.venv/bin/python -m bench.diag_vio_scale [SEED]`` (about 2 minutes on one core).
"""

from __future__ import annotations

import sys
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import NDArray

from amrvio.app.run import RunResult
from amrvio.app.run import run as run_recording
from amrvio.estimator import vio_backend
from amrvio.estimator.vio_landmarks import project_px
from amrvio.estimator.vio_types import VisualObservations
from amrvio.io.dataset import open_dataset
from amrvio.pipeline.threads import run_settings
from amrvio.sim.render import SceneRenderer
from amrvio.sim.scene import make_scene
from amrvio.sim.simulate import SimConfig, make_camera, simulate
from amrvio.types.lie import SE3
from bench.bench_vio_pipeline import _causal_scale_time

F64 = NDArray[np.float64]
ObsFix = Callable[[int, VisualObservations], VisualObservations]


def _bilinear(img: NDArray[np.float32], u: float, v: float) -> float:
    """``img`` at pixel (u, v) (pixel centres at integers), bilinear; the depth at the rounded
    pixel alone puts a point on a floor seen at a grazing angle visibly off its true position."""
    u0, v0 = min(max(int(np.floor(u)), 0), img.shape[1] - 2), min(max(int(np.floor(v)), 0), img.shape[0] - 2)
    a, b = u - u0, v - v0
    q = img[v0:v0 + 2, u0:u0 + 2].astype(np.float64)
    return float((1 - b) * ((1 - a) * q[0, 0] + a * q[0, 1]) + b * ((1 - a) * q[1, 0] + a * q[1, 1]))


def _truth_fix(seq: Path, noise_px: float, reject_px: float | None) -> ObsFix:
    """The observation swap: true projections + ``noise_px`` noise, or (``reject_px``) the
    observations themselves less those further than ``reject_px`` from their true projection."""
    meta = yaml.safe_load((seq / "sim_config.yaml").read_text())
    conf = SimConfig(**meta["config"])
    renderer = SceneRenderer(make_scene(conf.scene, conf.seed), make_camera(conf))
    gt = open_dataset(str(seq)).groundtruth
    if gt is None:
        raise RuntimeError(f"{seq}: no ground truth")
    cam = meta["derived"]["camera"]
    K = np.array([[cam["fx"], 0.0, cam["cx"]], [0.0, cam["fy"], cam["cy"]], [0.0, 0.0, 1.0]])
    T_body_cam = np.array(meta["derived"]["T_body_cam"])
    # the renderer's scene frame (a replay's trajectory is shifted into the scene; identity else)
    T_scene_world = np.array(meta["derived"].get("T_scene_world", np.eye(4)))
    rng = np.random.default_rng(0)
    first: dict[int, F64 | None] = {}  # track id -> its true world point (None: on a depth edge)

    def fix(t_ns: int, obs: VisualObservations) -> VisualObservations:
        T_wc = gt.interpolated_at([t_ns * 1e-9]).matrices()[0] @ T_body_cam
        T_wc_se3, T_sc = SE3.from_matrix(T_wc), SE3.from_matrix(T_scene_world @ T_wc)
        new = [k for k, i in enumerate(obs.ids.tolist()) if i not in first]
        if new:
            depth = renderer.depth(T_sc)
            for k in new:
                u, v = obs.uv_px[k]
                iu, iv = int(round(u)), int(round(v))
                patch = depth[max(iv - 1, 0):iv + 2, max(iu - 1, 0):iu + 2]
                if not (0 <= iu < depth.shape[1] and 0 <= iv < depth.shape[0]) or not np.all(np.isfinite(patch)) \
                        or patch.max() - patch.min() > 0.05 * patch.min():
                    first[int(obs.ids[k])] = None
                    continue
                Xc = _bilinear(depth, u, v) * np.linalg.solve(K, [u, v, 1.0])
                first[int(obs.ids[k])] = (T_wc @ np.r_[Xc, 1.0])[:3]
        keep_ids, keep_uv = [], []
        for k, i in enumerate(obs.ids.tolist()):
            X = first.get(i)
            if X is None:
                continue
            uv_true, z = project_px(K, T_wc_se3, X[None])
            if z[0] <= 0.05:
                continue
            true_uv = uv_true[0]
            if reject_px is not None:
                if np.linalg.norm(obs.uv_px[k] - true_uv) <= reject_px:
                    keep_ids.append(i)
                    keep_uv.append(obs.uv_px[k])
                continue
            keep_ids.append(i)
            keep_uv.append(true_uv + noise_px * rng.standard_normal(2))
        if not keep_ids:
            return VisualObservations.empty()
        return VisualObservations(np.array(keep_ids, dtype=np.int64), np.array(keep_uv))

    return fix


@contextmanager
def _observations_swapped(fix: ObsFix | None) -> Iterator[None]:
    """Every observation the VIO back-end gets goes through ``fix`` (None: unchanged)."""
    if fix is None:
        yield
        return
    cls = vio_backend.VioBackend
    add, init = cls.add_frame, cls.initialise

    def add_frame(self: Any, t_ns: int, imu: Any, obs: VisualObservations, *a: Any, **k: Any) -> Any:
        return add(self, t_ns, imu, fix(t_ns, obs), *a, **k)

    def initialise(self: Any, state: Any, imu: Any = None, observations: VisualObservations | None = None) -> Any:
        if observations is not None:
            observations = fix(state.state.t_ns, observations)
        return init(self, state, imu, observations)

    cls.add_frame, cls.initialise = add_frame, initialise  # type: ignore[method-assign, assignment]
    try:
        yield
    finally:
        cls.add_frame, cls.initialise = add, init  # type: ignore[method-assign]


def speed_ratio(res: RunResult, seq: Path, t0_s: float = 1.0, t1_s: float = 3.0) -> float:
    """Mean |v_VIO| / |v_true| over the frames between ``t0_s`` and ``t1_s`` after the start."""
    gt = open_dataset(str(seq)).groundtruth
    assert gt is not None
    ratios = []
    for r in res.records:
        vio = r.estimator.vio
        if vio is None or vio.estimate is None or vio.estimate.state is None:
            continue
        t = r.t_ns * 1e-9
        if not t0_s <= t - float(gt.stamps_s[0]) <= t1_s:
            continue
        a, b = gt.interpolated_at([t - 0.01, t + 0.01]).positions_m
        ratios.append(float(np.linalg.norm(vio.estimate.state.v_world_m_s)) / float(np.linalg.norm(b - a) / 0.02))
    return float(np.mean(ratios)) if ratios else float("nan")


def main(argv: list[str]) -> int:
    seed = int(argv[0]) if argv else 0
    run_settings()  # as `amrvio run` does
    work = Path(tempfile.mkdtemp(prefix="diag_vio_scale_"))
    seq = work / f"fst{seed}"
    simulate(SimConfig(motion="forward-stop-turn", seconds=8.0, width=376, height=240, seed=seed), seq, force=True)
    variants: list[tuple[str, Callable[[], ObsFix | None]]] = [
        ("tracks", lambda: None),
        ("true+0.3px", lambda: _truth_fix(seq, 0.3, None)),
        ("true+0.01px", lambda: _truth_fix(seq, 0.01, None)),
        ("tracks>1px out", lambda: _truth_fix(seq, 0.0, 1.0)),
    ]
    print(f"forward-stop-turn seed {seed}: mean online speed / true speed over 1.0-3.0 s; time to 2 % causal scale")
    for window in (10, 40):
        for name, make in variants:
            with _observations_swapped(make()):
                res = run_recording(str(seq), {"vio": {"window_keyframes": window}}, out=work / "out", report=False,
                                    force=True)
            after, _ = _causal_scale_time(res, seq)
            ratio = speed_ratio(res, seq)
            print(f"  window {window:2d}  {name:15s} speed ratio {ratio:.4f}  2 % scale after {after:.3f} s",
                  flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
