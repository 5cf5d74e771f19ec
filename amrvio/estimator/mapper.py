"""Mapping stage of the monocular VO: triangulation of new points, local sliding-window bundle
adjustment and outlier culling, all on one :class:`VoMap` (the only place it changes).

The mapper knows nothing about images or the pipeline: it takes keyframe poses and track
observations, and returns what it did.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from amrvio.estimator.ba_schur import solve_ba_schur
from amrvio.estimator.local_ba import (
    BAProblem,
    BAReport,
    BAResult,
    BAStatus,
    solve_ba_gtsam,
    solve_ba_scipy,
)
from amrvio.estimator.vo_map import VoMap
from amrvio.geometry.projection import MIN_DEPTH, pixels_to_normalized, project
from amrvio.geometry.triangulation import triangulate

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]
log = logging.getLogger(__name__)

BA_BACKENDS = ("schur", "gtsam", "scipy")
BA_MIN_POINTS = 10  # a local BA needs this many points seen by two keyframes of the window


@dataclass(frozen=True, slots=True)
class MapperConfig:
    """Local BA over the last ``ba_window`` keyframes plus ``ba_fixed`` held ones (gauge);
    ``ba_backend``: "gtsam" (LM, SEQUENTIAL_CHOLESKY; bench_ba_solvers), "schur" (the same LM in
    NumPy on the reduced camera system, ``estimator.ba_schur``; about half the time, bench_speed)
    or "scipy" (least_squares, converges more slowly: bench_vo). ``tri_max_reproj_px``: a new
    point's largest reprojection error, the 95 % gate of a two-dimensional error of 1 px
    (sqrt(5.991), as ORB-SLAM gates its points); at 1 px, a quarter to a third of the candidates
    of KITTI 00's turn (every third frame) were rejected, and the map thinned to 12-57 PnP
    inliers a frame there."""

    ba_window: int = 8
    ba_fixed: int = 2
    ba_backend: str = "gtsam"
    ba_iterations: int = 8
    huber_px: float = 2.0
    cull_px: float = 2.5
    tri_min_parallax_deg: float = 1.0
    tri_max_reproj_px: float = 2.45


@dataclass(frozen=True, slots=True)
class TriangulationReport:
    """What one ``Mapper.triangulate_new`` did. ``n_candidates``: tracks seen in an earlier
    keyframe and without a point; ``n_created``: new map points. Each rejected candidate is
    counted once, for the first failed check in this order: behind a camera, parallax below
    ``tri_min_parallax_deg``, reprojection error above ``tri_max_reproj_px``."""

    n_candidates: int
    n_created: int
    n_behind_camera: int
    n_low_parallax: int
    n_large_reprojection: int


class Mapper:
    """Owns one segment's map. ``timings`` accumulates seconds per stage name."""

    def __init__(self, K: F64, config: MapperConfig) -> None:
        if config.ba_backend not in BA_BACKENDS:
            raise ValueError(f"ba_backend must be one of {BA_BACKENDS}, got {config.ba_backend!r}")
        self.cfg = config
        self.K = K
        self.map = VoMap()
        self.timings: dict[str, float] = {}

    def _toc(self, stage: str, t0: float) -> None:
        self.timings[stage] = self.timings.get(stage, 0.0) + time.perf_counter() - t0

    def triangulate_new(self, kf_id: int, track_ids: I64, first_kf: I64, first_uv: F64,
                        uv: F64, n_tracks_total: int) -> TriangulationReport:
        """Triangulate tracks seen in an earlier keyframe (``first_kf`` (N,), ``first_uv``
        (N, 2)) and now at ``uv`` (N, 2) in keyframe ``kf_id``; those without a point yet.
        ``first_kf`` < 0: the track has no earlier keyframe (not a candidate)."""
        t0 = time.perf_counter()
        m = self.map
        T_cw = m.keyframes[kf_id].T_cam_world
        m.ensure_capacity(n_tracks_total)
        has = m.points_of(track_ids)
        cand = np.flatnonzero(~has & (first_kf >= 0) & (first_kf < kf_id))
        n_new = n_behind = n_parallax = n_reproj = 0
        if len(cand):
            focal = 0.5 * (self.K[0, 0] + self.K[1, 1])
            xn2 = pixels_to_normalized(uv[cand], self.K)
            xn1 = pixels_to_normalized(first_uv[cand], self.K)
            X = np.zeros((len(cand), 3))
            valid = np.zeros(len(cand), dtype=bool)
            in_front = np.zeros(len(cand), dtype=bool)
            parallax_ok = np.zeros(len(cand), dtype=bool)
            for fk in np.unique(first_kf[cand]):
                sel = first_kf[cand] == fk
                tri = triangulate(m.keyframes[int(fk)].T_cam_world, T_cw, xn1[sel], xn2[sel],
                                  min_parallax_deg=self.cfg.tri_min_parallax_deg,
                                  max_reproj_px=self.cfg.tri_max_reproj_px, focal_px=focal)
                X[sel] = tri.points_world
                valid[sel] = tri.valid
                in_front[sel] = tri.in_front
                parallax_ok[sel] = tri.parallax_deg >= self.cfg.tri_min_parallax_deg
            m.set_points(track_ids[cand[valid]], X[valid])
            n_new = int(valid.sum())
            n_behind = int((~in_front).sum())
            n_parallax = int((in_front & ~parallax_ok).sum())
            n_reproj = int((in_front & parallax_ok & ~valid).sum())
        self._toc("triangulate", t0)
        return TriangulationReport(len(cand), n_new, n_behind, n_parallax, n_reproj)

    def local_ba(self) -> BAReport:
        """Bundle-adjust the newest keyframes and their points, then cull points with a
        large residual or behind a camera."""
        cfg = self.cfg
        m = self.map
        t0 = time.perf_counter()
        win = m.keyframes[-(cfg.ba_window + cfg.ba_fixed):]
        ids_all = np.concatenate([k.track_ids for k in win])
        cams = np.concatenate([np.full(len(k.track_ids), i) for i, k in enumerate(win)])
        uvs = np.vstack([k.uv for k in win])
        has = m.points_of(ids_all)
        ids_all, cams, uvs = ids_all[has], cams[has], uvs[has]
        _, inv, counts = np.unique(ids_all, return_inverse=True, return_counts=True)
        good = counts[inv] >= 2
        ids_all, cams, uvs = ids_all[good], cams[good], uvs[good]
        uniq2, inv2 = np.unique(ids_all, return_inverse=True)
        n_obs = len(ids_all)
        if len(uniq2) < BA_MIN_POINTS:
            self._toc("ba", t0)
            return BAReport(BAStatus.TOO_FEW_POINTS, len(win), len(uniq2), n_obs)
        # gauge (7 DoF): hold the older keyframes fixed, at least two of them
        fixed_all = np.zeros(len(win), dtype=bool)
        fixed_all[: max(2, len(win) - cfg.ba_window)] = True
        # keyframes without an observation in this window stay out of the problem
        used, cams = np.unique(cams, return_inverse=True)
        win = [win[int(i)] for i in used]
        fixed = fixed_all[used]
        if int(fixed.sum()) < 2:
            fixed[:2] = True
        if len(win) < 2:
            self._toc("ba", t0)
            return BAReport(BAStatus.TOO_FEW_KEYFRAMES, len(win), len(uniq2), n_obs)
        T = np.stack([k.T_cam_world for k in win])
        prob = BAProblem(T, fixed, m.xyz[uniq2].copy(), cams.astype(np.int64),
                         inv2.astype(np.int64), uvs, self.K, cfg.huber_px)
        out = self._solve(prob)
        if out is None:
            self._toc("ba", t0)
            return BAReport(BAStatus.SOLVER_FAILED, len(win), len(uniq2), n_obs)
        for i, k in enumerate(win):
            m.set_pose(k.kf_id, out.T_cam_world[i])
        m.xyz[uniq2] = out.points
        self._toc("ba", t0)
        # culling: points with a large residual or behind a camera
        t0 = time.perf_counter()
        _, z = project(self.K, out.T_cam_world[cams], out.points[inv2])
        bad_obs = (out.residual_px > cfg.cull_px) | (z <= MIN_DEPTH)
        bad_pts = np.unique(inv2[bad_obs])
        m.remove_points(uniq2[bad_pts])
        self._toc("cull", t0)
        return BAReport(BAStatus.OK, len(win), len(uniq2), n_obs, out.iterations,
                        _rms(out.initial_residual_px), _rms(out.residual_px), len(bad_pts))

    def _solve(self, prob: BAProblem) -> BAResult | None:
        solver = {"schur": solve_ba_schur, "gtsam": solve_ba_gtsam,
                  "scipy": solve_ba_scipy}[self.cfg.ba_backend]
        try:
            return solver(prob, self.cfg.ba_iterations)
        except (RuntimeError, np.linalg.LinAlgError) as err:  # gtsam: indeterminant system
            log.warning("local BA failed: %s", err)
            return None


def _rms(err_px: F64) -> float:
    return float(np.sqrt(np.mean(err_px * err_px))) if len(err_px) else 0.0


__all__ = ["BA_BACKENDS", "BA_MIN_POINTS", "BAReport", "BAStatus", "Mapper", "MapperConfig",
           "TriangulationReport"]
