"""The landmarks of the VIO back-end: tracks waiting for parallax, landmarks in the smoother, and
the multi-view triangulation that turns the former into the latter (poses known).

A track (a landmark id of the front-end) collects its observations, one per keyframe, while it
is *pending*. Once its rays span ``min_parallax_deg`` it is triangulated from the current pose
estimates (least-squares intersection of the rays, Hartley & Zisserman 2003, §12.2's midpoint
generalised to N views) and, if it lies in front of every camera within the depth range and
reprojects within the gate, it enters the smoother as a landmark with all its observations.
Observations of keyframes that left the window are dropped from pending tracks. A landmark leaves
the smoother with the first keyframe that saw it (as in VINS-Mono, where a feature is anchored in
its first frame): marginalising that keyframe then makes a dense prior on the remaining
keyframes' states only, never on other landmarks, so the window stays sparse. The landmark's id
starts a new track if the front-end keeps observing it; the old observations live on in the
prior, so nothing is counted twice.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from amrvio.types.lie import SE3

F64 = NDArray[np.float64]


def project_px(K: F64, T_world_cam: SE3, X_world: F64) -> tuple[F64, F64]:
    """Pixels (N, 2) and depths (N,) of world points (N, 3) in a pinhole camera."""
    p = (np.asarray(X_world) - T_world_cam.t) @ T_world_cam.R  # R^T (X - t), row-wise
    z = p[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = np.stack([K[0, 0] * p[:, 0] / z + K[0, 2], K[1, 1] * p[:, 1] / z + K[1, 2]], axis=1)
    return uv, z


def range_ratio_within(X_world: F64, centres_first: F64, centre_now: F64, limit: float) -> NDArray[np.bool_]:
    """Whether each landmark's (N, 3) distance from the camera centre ``centre_now`` is within
    ``limit`` (natural log of the ratio) of its distance from its first keyframe's centre (N, 3):
    the scale change of its image patch, which a rotation does not change."""
    r0 = np.linalg.norm(X_world - centres_first, axis=1)
    r1 = np.linalg.norm(X_world - centre_now, axis=1)
    ok = (r0 > 0) & (r1 > 0)
    return ok & (np.abs(np.log(np.where(ok, r0, 1.0) / np.where(ok, r1, 1.0))) <= limit)


@dataclass(frozen=True, slots=True, eq=False)
class TrackTriangulation:
    """Per track (T tracks): the point closest to its rays in the least-squares sense (T, 3), the
    largest angle between its newest ray and another of its rays (deg, (T,)), and whether the
    normal equations were well conditioned (T,)."""

    points_world: F64
    parallax_deg: F64
    ok: NDArray[np.bool_]


def triangulate_tracks(track: NDArray[np.int64], centers: F64, rays: F64, n_tracks: int) -> TrackTriangulation:
    """For each track t, minimise sum_i |(I - d_i d_i^T)(X - o_i)|^2 over the rays (o_i, unit d_i)
    with ``track[i] == t``; a track's rays are consecutive, its newest last.

    track (M,) sorted track index of each ray; centers (M, 3) ray origins; rays (M, 3) unit.
    """
    P = np.eye(3)[None] - rays[:, :, None] * rays[:, None, :]
    A = np.zeros((n_tracks, 3, 3))
    b = np.zeros((n_tracks, 3))
    np.add.at(A, track, P)
    np.add.at(b, track, np.einsum("nij,nj->ni", P, centers))
    last = np.r_[np.flatnonzero(np.diff(track)), track.shape[0] - 1]  # index of each track's newest ray
    cosines = np.einsum("ni,ni->n", rays, rays[last[track]])
    min_cos = np.ones(n_tracks)
    np.minimum.at(min_cos, track, cosines)
    parallax = np.degrees(np.arccos(np.clip(min_cos, -1.0, 1.0)))
    smallest = np.linalg.eigvalsh(A)[:, 0]
    ok = smallest > 1e-9
    X = np.full((n_tracks, 3), np.nan)
    if ok.any():
        X[ok] = np.linalg.solve(A[ok], b[ok][:, :, None])[:, :, 0]
    return TrackTriangulation(X, parallax, ok)


@dataclass(slots=True)
class Landmark:
    """A landmark in the smoother: its GTSAM key and the first keyframe that observed it (the
    smoother marginalises the landmark together with that keyframe)."""

    key: int
    first_keyframe: int


@dataclass(slots=True)
class LandmarkTracks:
    """Pending tracks and active landmarks, by front-end id (see the module docstring).

    pending: id -> [(keyframe index, uv (2,))]; active: id -> Landmark; seeds: id -> a world
    position the initialiser already had (the starting guess instead of triangulation);
    typical_depth_m: the median distance of the landmarks the newest frame that saw any saw.
    """

    pending: dict[int, list[tuple[int, F64]]] = field(default_factory=dict)
    active: dict[int, Landmark] = field(default_factory=dict)
    seeds: dict[int, F64] = field(default_factory=dict)
    next_key: int = 0
    typical_depth_m: float | None = None

    def observe_pending(self, lm_id: int, kf: int, uv: F64) -> None:
        self.pending.setdefault(lm_id, []).append((kf, np.asarray(uv, dtype=np.float64)))

    def activate(self, lm_id: int, kf: int) -> int:
        """Move a pending track into the smoother (``kf``: its first keyframe); returns its new
        key index."""
        key = self.next_key
        self.next_key += 1
        self.pending.pop(lm_id, None)
        self.seeds.pop(lm_id, None)
        self.active[lm_id] = Landmark(key, kf)
        return key

    def retire(self, lm_ids: list[int]) -> None:
        """End the landmarks of these front-end ids: their tracks go on as new pending tracks
        (the smoother keeps the old landmarks with the views they had)."""
        for lm_id in lm_ids:
            self.active.pop(lm_id, None)

    def forget_before(self, first_kf: int) -> None:
        """Drop what refers only to keyframes older than ``first_kf`` (they left the window)."""
        for lm_id in [i for i, lm in self.active.items() if lm.first_keyframe < first_kf]:
            del self.active[lm_id]
        for lm_id in list(self.pending):
            kept = [o for o in self.pending[lm_id] if o[0] >= first_kf]
            if kept:
                self.pending[lm_id] = kept
            else:
                del self.pending[lm_id]


__all__ = ["Landmark", "LandmarkTracks", "TrackTriangulation", "project_px", "range_ratio_within", "triangulate_tracks"]
