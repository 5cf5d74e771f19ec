"""New landmarks for the VIO back-end: the pending tracks seen by a new keyframe are triangulated
from the window's poses (all at once, :func:`amrvio.estimator.vio_landmarks.triangulate_tracks`)
and enter the graph with every observation; and the parallax that makes a frame a keyframe."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from amrvio.estimator.vio_graph import Camera, sym
from amrvio.estimator.vio_landmarks import LandmarkTracks, triangulate_tracks
from amrvio.estimator.vio_types import VisualConfig, VisualObservations
from amrvio.types.lie import SE3

if TYPE_CHECKING:
    import gtsam

F64 = NDArray[np.float64]


def keyframe_parallax_deg(points_world: F64, center_a: F64, center_b: F64) -> float:
    """Median over the points (N, 3) of the angle at the point between the two camera centres
    (the parallax a translation from ``a`` to ``b`` makes, free of rotation); 0 without points."""
    if points_world.shape[0] == 0:
        return 0.0
    da = points_world - center_a
    db = points_world - center_b
    cos = np.einsum("ni,ni->n", da, db) / (np.linalg.norm(da, axis=1) * np.linalg.norm(db, axis=1))
    return float(np.degrees(np.median(np.arccos(np.clip(cos, -1.0, 1.0)))))


def keyframe_due(points_seen: F64, center_last_kf: F64, center_now: F64, typical_depth_m: float | None,
                 vis: VisualConfig) -> bool:
    """Whether a frame that sees the landmarks ``points_seen`` (N, 3), with its camera centre at
    ``center_now``, becomes a keyframe: when their median parallax from the last keyframe's centre
    reaches ``keyframe_parallax_deg``, or when it sees fewer than ``min_tracked_landmarks`` and
    has moved far enough from that keyframe for new landmarks: ``keyframe_parallax_deg`` at
    ``typical_depth_m`` (the median distance of the landmarks seen lately; None: not known, any
    move). A keyframe that adds no baseline triangulates nothing, and each one slides the window:
    standing or turning in place with few landmarks in view, a keyframe on every frame
    marginalised the window's landmarks within ``window_keyframes`` frames."""
    if points_seen.shape[0] < max(vis.min_tracked_landmarks, 1):
        if typical_depth_m is None:
            return True
        baseline = float(np.linalg.norm(np.asarray(center_now) - np.asarray(center_last_kf)))
        return baseline >= typical_depth_m * float(np.tan(np.radians(vis.keyframe_parallax_deg)))
    return keyframe_parallax_deg(points_seen, center_last_kf, center_now) >= vis.keyframe_parallax_deg


def triangulate_pending(tracks: LandmarkTracks, obs: VisualObservations, k: int, cams: dict[int, SE3],
                        ordinals: dict[int, int], cam: Camera, vis: VisualConfig, graph: gtsam.NonlinearFactorGraph,
                        values: gtsam.Values,
                        stamps: dict[int, float], used: list[tuple[int, F64]], seed_sigma_m: float) -> int:
    """Landmarks from the pending tracks observed by keyframe ``k`` whose rays span
    ``min_parallax_deg``, and from those the initialiser located (a seed: it needs one
    observation, no parallax, and gets a prior of ``seed_sigma_m``); returns how many were created.

    ``cams``: T_world_cam of every keyframe a pending observation refers to (frame ``k``: its
    prediction); ``ordinals``: their smoother times. A new landmark's factors go into ``graph``,
    its position (the initialiser's seed, else the triangulation) into ``values``, its smoother
    time (its first keyframe's) into ``stamps``, and its observation at ``k`` into ``used``. A
    track with the parallax that lands behind a camera, out of the depth range or further than
    ``gate_px`` from one of its pixels is dropped (an outlier in it, or a point at infinity).
    A triangulated landmark also gets the weak prior of ``vis.landmark_prior_range``.
    """
    import gtsam

    ids = [lm_id for lm_id in obs.ids.tolist()
           if len(tracks.pending.get(lm_id, ())) >= (1 if lm_id in tracks.seeds else 2)
           and tracks.pending[lm_id][-1][0] == k]
    if not ids:
        return 0
    kfs = [kf for lm_id in ids for kf, _ in tracks.pending[lm_id]]
    uv = np.array([uv for lm_id in ids for _, uv in tracks.pending[lm_id]])
    track = np.repeat(np.arange(len(ids)), [len(tracks.pending[lm_id]) for lm_id in ids])
    R = np.array([cams[kf].R for kf in kfs])
    c = np.array([cams[kf].t for kf in kfs])
    d = np.einsum("nij,nj->ni", R, np.c_[uv, np.ones(len(uv))] @ cam.K_inv.T)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    tri = triangulate_tracks(track, c, d, len(ids))
    X = tri.points_world.copy()
    seeded = np.array([lm_id in tracks.seeds for lm_id in ids])
    for t in np.flatnonzero(seeded).tolist():
        X[t] = tracks.seeds[ids[t]]
    pc = np.einsum("nji,nj->ni", R, X[track] - c)  # R^T (X - c) per observation
    z = pc[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        proj = np.stack([cam.K[0, 0] * pc[:, 0] / z + cam.K[0, 2], cam.K[1, 1] * pc[:, 1] / z + cam.K[1, 2]], 1)
    err = np.nan_to_num(np.linalg.norm(proj - uv, axis=1), nan=np.inf)
    bad = ~((z > vis.min_depth_m) & (z < vis.max_depth_m) & (err <= vis.gate_px))
    track_bad = np.zeros(len(ids), dtype=bool)
    np.logical_or.at(track_bad, track, bad)
    ready = seeded | (tri.ok & (tri.parallax_deg >= vis.min_parallax_deg))
    seed_noise = gtsam.noiseModel.Isotropic.Sigma(3, seed_sigma_m)
    first_obs = np.searchsorted(track, np.arange(len(ids)))  # each track's first row (rows are grouped)
    n_new = 0
    for t in np.flatnonzero(ready).tolist():
        lm_id = ids[t]
        if track_bad[t]:
            del tracks.pending[lm_id]
            tracks.seeds.pop(lm_id, None)
            continue
        if seeded[t]:
            graph.add(gtsam.PriorFactorPoint3(sym("l", tracks.next_key), X[t], seed_noise))
        elif vis.landmark_prior_range > 0:
            rng = float(np.linalg.norm(X[t] - c[first_obs[t]]))  # from its first camera
            weak = gtsam.noiseModel.Isotropic.Sigma(3, vis.landmark_prior_range * rng)
            graph.add(gtsam.PriorFactorPoint3(sym("l", tracks.next_key), X[t], weak))
        track_obs = tracks.pending[lm_id]
        first = track_obs[0][0]
        key = tracks.activate(lm_id, first)
        values.insert(sym("l", key), np.asarray(X[t]))
        stamps[sym("l", key)] = float(ordinals[first])
        for kf, uv_i in track_obs:
            graph.add(cam.factor(uv_i, kf, key))
        used.append((key, track_obs[-1][1]))
        n_new += 1
    return n_new


def landmark_prior_share(prior_range: float, parallax_deg: float, pixel_sigma_px: float, focal_px: float) -> float:
    """The share of a landmark's depth information that its weak prior holds: a prior of
    ``prior_range`` ranges against two views whose rays meet at ``parallax_deg``, each with
    ``pixel_sigma_px`` of noise at focal length ``focal_px``. First order, the depth sigma of
    that pair is range * (pixel_sigma / focal) * sqrt(2) / parallax; the share is
    info_prior / (info_prior + info_views)."""
    if prior_range <= 0:
        return 0.0
    depth_rel = (pixel_sigma_px / focal_px) * np.sqrt(2.0) / np.radians(parallax_deg)
    info_views, info_prior = 1.0 / depth_rel**2, 1.0 / prior_range**2
    return float(info_prior / (info_prior + info_views))


__all__ = ["keyframe_due", "keyframe_parallax_deg", "landmark_prior_share", "triangulate_pending"]
