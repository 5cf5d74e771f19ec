"""Relocalisation: find a frame in an existing map after tracking was lost.

At keyframe creation, :meth:`KeyframeDatabase.add` describes the keyframe's tracked pixels with
ORB (:mod:`amrvio.tracking.orb`) and stores the descriptors with the track ids (= map point ids of
:class:`~amrvio.estimator.vo_map.VoMap`). :func:`relocalize` describes the lost frame (corners of
the tracker's detector plus multi-scale ORB features), ranks the keyframes by bag-of-words score
(:mod:`amrvio.tracking.vocabulary`), matches the frame to the map points of the best few that
still exist (nearest neighbour within a vocabulary node, Lowe's ratio test) and solves PnP RANSAC
(:func:`~amrvio.geometry.pnp.solve_pnp`) on those matches. A pose is then confirmed by a guided
search: the map points of the candidate keyframes are projected with it, matched to the frame's
features near their projection, and the pose is refined on all of them. It is accepted with at
least ``min_inliers`` inliers after that refinement, so a frame that shows another place gives a
status, not a wrong pose. This is ORB-SLAM's relocalisation (Mur-Artal and Tardos 2017, sec. V-C)
with a vocabulary trained on the map's own descriptors.

Poses are 4x4 ``T_cam_world`` arrays in the map's own frame and units.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from enum import Enum

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from amrvio.errors import ConfigError, ShapeError
from amrvio.estimator.keyframe_db import KeyframeDatabase, KeyframeEntry
from amrvio.estimator.vo_map import VoMap
from amrvio.geometry.pnp import refine_pose_huber, solve_pnp
from amrvio.geometry.projection import MIN_DEPTH, project
from amrvio.tracking.detect import DetectorConfig, detect_corners
from amrvio.tracking.orb import (
    DESCRIPTOR_BYTES,
    EDGE_PX,
    SCALE_FACTOR,
    OrbFeatures,
    describe_at,
    detect_orb,
    hamming,
    hamming_matrix,
)

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]
U8 = NDArray[np.uint8]

CORNER_CELLS = 64
"""Grid cells over which the query's corners are spread."""


@dataclass(frozen=True, slots=True)
class RelocConfig:
    """Relocalisation settings. The gates follow ORB-SLAM's relocalisation (Mur-Artal and Tardos
    2017): Lowe's ratio 0.75 and Hamming <= 50 (of 256 bits) for appearance matches, >= 15 of them
    to try a keyframe, then a search by projection within 10 pixels and Hamming <= 100; the PnP
    gate is the tracker's 2-pixel Huber scale.

    ``n_corners``: Shi-Tomasi corners described in the query image (the detector the tracker uses,
    so they land where the keyframes' tracks were); ``n_features``: multi-scale ORB features added
    to them (8 levels of scale 1.2; 0 = none). ``max_candidates``: keyframes tried, best bag-of-words score first,
    and the ``recent_candidates`` newest keyframes too (where the camera was last seen: a vocabulary
    trained on the map's own descriptors scores a small map's keyframes alike, 0.45-0.48 after the
    simulated corridor's black-out, and the keyframe that held the view ranked below the third;
    more candidates by score instead let a repeated texture elsewhere in the warehouse in).
    ``pnp_thresh_px``: inlier gate at pyramid level 0 (times 1.2^level for coarser features).
    ``min_inliers``: inliers of the final pose needed to accept it.
    """

    n_corners: int = 2000
    n_features: int = 1000
    ratio: float = 0.75
    max_hamming: int = 50
    min_matches: int = 15
    max_candidates: int = 3
    recent_candidates: int = 3
    pnp_thresh_px: float = 2.0
    min_inliers: int = 30
    search_radius_px: float = 10.0
    guided_max_hamming: int = 100

    def __post_init__(self) -> None:
        if self.max_candidates < 1 or self.recent_candidates < 0:
            raise ConfigError("RelocConfig.max_candidates must be >= 1 and recent_candidates >= 0, got "
                              f"{self.max_candidates} and {self.recent_candidates}")
        if self.n_corners < 0 or self.n_features < 0 or self.n_corners + self.n_features == 0:
            raise ConfigError("RelocConfig.n_corners and n_features must be >= 0 and not both 0, "
                              f"got {self.n_corners} and {self.n_features}")
        if not 0.0 < self.ratio <= 1.0:
            raise ConfigError(f"RelocConfig.ratio must be in (0, 1], got {self.ratio}")
        for name, h in (("max_hamming", self.max_hamming),
                        ("guided_max_hamming", self.guided_max_hamming)):
            if not 0 <= h <= 8 * DESCRIPTOR_BYTES:
                raise ConfigError(f"RelocConfig.{name} must be in [0, 256], got {h}")
        if self.min_matches < 6 or self.min_inliers < 6:
            raise ConfigError("RelocConfig.min_matches and min_inliers must be >= 6 (PnP needs "
                              f"6 points), got {self.min_matches} and {self.min_inliers}")
        if not (self.pnp_thresh_px > 0 and self.search_radius_px > 0):
            raise ConfigError("RelocConfig.pnp_thresh_px and search_radius_px must be positive, "
                              f"got {self.pnp_thresh_px} and {self.search_radius_px}")


class RelocStatus(Enum):
    """Outcome of a relocalisation attempt."""

    OK = "ok"
    NO_CANDIDATE = "no_candidate"  # the database has no keyframe with a live map point
    NO_FEATURES = "no_features"  # too few ORB features in the image (dark, uniform, blurred)
    TOO_FEW_MATCHES = "too_few_matches"  # no keyframe shares min_matches matches with the image
    PNP_FAILED = "pnp_failed"  # matches, but no pose with min_inliers inliers


@dataclass(frozen=True, slots=True)
class RelocResult:
    """A relocalisation attempt. When OK: the keyframe it matched, ``T_cam_world`` (4x4, map
    frame), and the inliers: (K,) map point ids (unique, increasing) with their (K, 2) pixels in
    the query image. ``n_matches``: descriptor matches of the best keyframe tried;
    ``n_inliers``: inliers of the best pose tried (also when rejected); ``n_features``: ORB
    features of the image; ``seconds``: wall time of the attempt."""

    status: RelocStatus
    kf_id: int | None
    T_cam_world: F64 | None
    point_ids: I64
    uv: F64
    n_features: int
    n_matches: int
    n_inliers: int
    seconds: float

    @property
    def ok(self) -> bool:
        return self.status is RelocStatus.OK


def describe_query(image: U8, config: RelocConfig) -> OrbFeatures:
    """The ORB features :func:`relocalize` uses for ``image`` (compute once, try several maps)."""
    if image.ndim != 2 or image.dtype != np.uint8:
        raise ShapeError(f"relocalize expects an (H, W) uint8 image, got {image.shape} {image.dtype}")
    parts = []
    if config.n_corners > 0:
        # about 64 square-ish cells (4 x 16 on KITTI's 1241 x 376, 7 x 9 on 640 x 480)
        h, w = image.shape
        rows = max(1, round(float(np.sqrt(CORNER_CELLS * h / w))))
        cols = max(1, round(CORNER_CELLS / rows))
        det = DetectorConfig(max_corners=config.n_corners, quality_level=0.001, min_distance_px=5,
                             block_size=5, border_px=EDGE_PX, grid_rows=rows, grid_cols=cols)
        c = detect_corners(image, det)
        idx, d = describe_at(image, c)
        parts.append(OrbFeatures(c[idx], d, np.zeros(len(idx), dtype=np.int64)))
    if config.n_features > 0:
        parts.append(detect_orb(image, config.n_features))
    return OrbFeatures(np.concatenate([p.uv for p in parts]),
                       np.concatenate([p.descriptors for p in parts]),
                       np.concatenate([p.octave for p in parts]))


def _node_matches(q: U8, q_node: I64, d: U8, d_node: I64, ratio: float,
                  max_hamming: int) -> tuple[I64, I64]:
    """Indices (query, database) of appearance matches between descriptors of the same
    vocabulary node (ORB-SLAM's search by bag of words): the nearest database descriptor when it
    is within ``max_hamming`` and closer than ``ratio`` times the second nearest of the node (256
    when the node has one); each database row used once (the closest query kept)."""
    qi: list[I64] = []
    di: list[I64] = []
    dist: list[I64] = []
    for node in np.intersect1d(q_node, d_node):
        a = np.flatnonzero(q_node == node)
        b = np.flatnonzero(d_node == node)
        H = hamming_matrix(q[a], d[b])
        j = np.argmin(H, axis=1)
        best = H[np.arange(len(a)), j]
        if len(b) > 1:
            second = np.partition(H, 1, axis=1)[:, 1]
        else:
            second = np.full(len(a), 8 * DESCRIPTOR_BYTES)
        ok = (best <= max_hamming) & (best < ratio * second)
        qi.append(a[ok])
        di.append(b[j[ok]])
        dist.append(best[ok])
    if not qi:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    qa, da, ha = np.concatenate(qi), np.concatenate(di), np.concatenate(dist)
    order = np.lexsort((qa, ha))
    _, first = np.unique(da[order], return_index=True)
    keep = np.sort(order[first])
    return qa[keep].astype(np.int64), da[keep].astype(np.int64)


def _guided_matches(feats: OrbFeatures, T: F64, K: F64, shape_hw: tuple[int, int], vomap: VoMap,
                    local: list[KeyframeEntry], config: RelocConfig) -> tuple[I64, I64]:
    """(query index, point id) matches of the map points seen by the ``local`` keyframes that
    project near a query feature under the pose ``T`` with a close descriptor; each point and
    each feature used once (the smallest Hamming distance first)."""
    ids = np.concatenate([e.point_ids for e in local])
    desc = np.concatenate([e.descriptors for e in local])
    live = vomap.points_of(ids)
    ids, desc = ids[live], desc[live]
    uv, z = project(K, T, vomap.xyz[ids])
    h, w = shape_hw
    vis = (z > MIN_DEPTH) & (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
    ids, desc, uv = ids[vis], desc[vis], uv[vis]
    none = np.zeros(0, dtype=np.int64)
    if len(ids) == 0:
        return none, none
    near = cKDTree(feats.uv).query_ball_point(uv, config.search_radius_px)
    rows = np.repeat(np.arange(len(ids)), [len(n) for n in near])
    if len(rows) == 0:
        return none, none
    cols = np.concatenate([np.asarray(n, dtype=np.int64) for n in near])
    dist = hamming(desc[rows], feats.descriptors[cols])
    ok = dist <= config.guided_max_hamming
    rows, cols, dist = rows[ok], cols[ok], dist[ok]
    # one-to-one: the closest feature of each point, then the closest point of each feature
    order = np.lexsort((cols, rows, dist))
    rows, cols = rows[order], cols[order]
    _, first = np.unique(ids[rows], return_index=True)
    first.sort()
    rows, cols = rows[first], cols[first]
    _, first = np.unique(cols, return_index=True)
    first.sort()
    return cols[first].astype(np.int64), ids[rows[first]].astype(np.int64)


def _verify(feats: OrbFeatures, T0: F64, K: F64, shape_hw: tuple[int, int], vomap: VoMap,
            local: list[KeyframeEntry], config: RelocConfig) -> tuple[F64, I64, I64]:
    """Guided search with the PnP pose ``T0``, Huber refinement on all guided matches, and the
    inliers of the refined pose (gate ``pnp_thresh_px`` times the feature's level scale).
    Returns (T_cam_world, inlier query indices, their point ids)."""
    qi, pid = _guided_matches(feats, T0, K, shape_hw, vomap, local, config)
    if len(qi) < 6:
        return T0, qi, pid
    X, u = vomap.xyz[pid], feats.uv[qi]
    gate = config.pnp_thresh_px * SCALE_FACTOR ** feats.octave[qi].astype(np.float64)
    T = refine_pose_huber(T0, X, u, K, huber_px=config.pnp_thresh_px)
    proj, z = project(K, T, X)
    inl = (np.linalg.norm(proj - u, axis=1) < gate) & (z > MIN_DEPTH)
    if int(inl.sum()) >= 6:
        T = refine_pose_huber(T, X[inl], u[inl], K, huber_px=config.pnp_thresh_px)
        proj, z = project(K, T, X)
        inl = (np.linalg.norm(proj - u, axis=1) < gate) & (z > MIN_DEPTH)
    return T, qi[inl], pid[inl]


def relocalize(query: U8 | OrbFeatures, K: F64, vomap: VoMap, db: KeyframeDatabase,
               config: RelocConfig | None = None, seed: int = 0,
               image_shape_hw: tuple[int, int] | None = None) -> RelocResult:
    """Find the pose of an undistorted (H, W) uint8 image (or its :func:`describe_query`
    features, then give ``image_shape_hw``) in the map ``vomap`` whose keyframes are in ``db``.
    ``K``: 3x3 pinhole matrix. A miss is a status, never an exception."""
    t0 = time.perf_counter()
    cfg = config if config is not None else RelocConfig()
    if isinstance(query, OrbFeatures):
        if image_shape_hw is None:
            raise ShapeError("relocalize: give image_shape_hw with precomputed features")
        feats, shape_hw = query, image_shape_hw
    else:
        feats, shape_hw = describe_query(query, cfg), (int(query.shape[0]), int(query.shape[1]))
    if np.shape(K) != (3, 3) or not np.all(np.isfinite(K)):
        raise ShapeError(f"relocalize: K must be a finite 3x3 matrix, got shape {np.shape(K)}")

    def result(status: RelocStatus, kf_id: int | None = None, T: F64 | None = None,
               qi: I64 | None = None, pid: I64 | None = None, n_match: int = 0,
               n_inl: int = 0) -> RelocResult:
        ids = np.zeros(0, dtype=np.int64) if pid is None else pid
        uv = np.zeros((0, 2)) if qi is None else feats.uv[qi]
        order = np.argsort(ids, kind="stable")
        return RelocResult(status, kf_id, T, ids[order], uv[order], len(feats), n_match, n_inl,
                           time.perf_counter() - t0)

    if not any(int(vomap.points_of(e.point_ids).sum()) >= cfg.min_matches for e in db.entries()):
        return result(RelocStatus.NO_CANDIDATE)
    if len(feats) < cfg.min_matches:
        return result(RelocStatus.NO_FEATURES)
    # the best keyframes by bag of words, then appearance matches to their live map points
    vocab = db.vocabulary()
    if vocab is None:
        return result(RelocStatus.NO_CANDIDATE)
    q_node, q_word = vocab.quantize(feats.descriptors)
    local = [e for _, e in db.rank(q_word)[: cfg.max_candidates]]
    newest = db.entries()[::-1][: cfg.recent_candidates]
    local += [e for e in newest if all(e.kf_id != c.kf_id for c in local)]
    tries: list[tuple[int, int, KeyframeEntry, I64, I64]] = []
    for i, e in enumerate(local):
        live = vomap.points_of(e.point_ids)
        qi, di = _node_matches(feats.descriptors, q_node, e.descriptors[live],
                               (db.words(e.kf_id)[live] // vocab.branching).astype(np.int64), cfg.ratio,
                               cfg.max_hamming)
        tries.append((len(qi), i, e, qi, e.point_ids[live][di]))
    tries.sort(key=lambda r: (-r[0], r[1]))
    best_match, best_inl = tries[0][0], 0
    if best_match < cfg.min_matches:
        return result(RelocStatus.TOO_FEW_MATCHES, n_match=best_match)
    for n_match, _, e, qi, pid in tries:
        if n_match < cfg.min_matches:
            break
        pnp = solve_pnp(vomap.xyz[pid], feats.uv[qi], K, ransac_thresh_px=cfg.pnp_thresh_px,
                        min_inliers=min(cfg.min_inliers, cfg.min_matches),
                        huber_px=cfg.pnp_thresh_px, seed=seed)
        best_inl = max(best_inl, int(pnp.inliers.sum()))
        if not pnp.ok:
            continue
        T, vq, vp = _verify(feats, pnp.T_cam_world, K, shape_hw, vomap, local, cfg)
        best_inl = max(best_inl, len(vq))
        if len(vq) >= cfg.min_inliers:
            return result(RelocStatus.OK, e.kf_id, T, vq, vp, n_match, len(vq))
    return result(RelocStatus.PNP_FAILED, n_match=best_match, n_inl=best_inl)


__all__ = ["KeyframeDatabase", "KeyframeEntry", "RelocConfig", "RelocResult", "RelocStatus",
           "describe_query", "relocalize"]
