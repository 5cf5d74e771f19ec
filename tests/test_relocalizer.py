"""Relocalisation: ORB at given pixels against OpenCV's own ORB, the binary vocabulary, the keyframe
database, and relocalize() against the simulator's ground truth (exact map points from the
rendered depth). The KITTI test is tests/data_real/test_relocalizer_kitti.py."""

from __future__ import annotations

import tracemalloc

import cv2
import numpy as np
import pytest
from numpy.typing import NDArray

from amrvio.errors import ConfigError, ShapeError
from amrvio.estimator.keyframe_db import KeyframeDatabase
from amrvio.estimator.relocalizer import (
    RelocConfig,
    RelocResult,
    RelocStatus,
    describe_query,
    relocalize,
)
from amrvio.estimator.vo_map import VoMap
from amrvio.geometry.projection import project
from amrvio.pipeline.recovery import MapRecovery, RecoveryConfig
from amrvio.sim.render import SceneRenderer
from amrvio.sim.scene import make_scene
from amrvio.tracking.detect import DetectorConfig, detect_corners
from amrvio.tracking.orb import (
    EDGE_PX,
    centroid_angles_deg,
    describe_at,
    detect_orb,
    hamming,
    hamming_matrix,
)
from amrvio.tracking.vocabulary import Vocabulary, _majority, bow_scores, k_majority
from amrvio.types.camera import PinholeCamera
from amrvio.types.lie import SE3, SO3

F64 = NDArray[np.float64]
U8 = NDArray[np.uint8]

# ---------------------------------------------------------------------------------------------
# ORB at given pixels
# ---------------------------------------------------------------------------------------------


def _texture(h: int = 240, w: int = 320, seed: int = 0) -> U8:
    """Blurred random blobs: corners everywhere, no symmetry."""
    rng = np.random.default_rng(seed)
    img = cv2.GaussianBlur(rng.uniform(0, 255, (h, w)).astype(np.float32), (0, 0), 2.0)
    img = cv2.normalize(img, None, 0, 255, cv2.NORM_MINMAX)
    return np.asarray(img, dtype=np.uint8)


def test_describe_at_reproduces_opencv_orb_at_its_own_keypoints() -> None:
    img = _texture()
    kps, desc = cv2.ORB.create(nfeatures=1000).detectAndCompute(img, None)
    lvl0 = [i for i, k in enumerate(kps) if k.octave == 0]
    assert len(lvl0) > 100
    uv = np.array([kps[i].pt for i in lvl0])
    ref_angle = np.array([kps[i].angle for i in lvl0])
    diff = (centroid_angles_deg(img, uv) - ref_angle + 180.0) % 360.0 - 180.0
    assert np.max(np.abs(diff)) < 0.05  # the same intensity-centroid orientation
    idx, d = describe_at(img, uv)
    assert len(idx) == len(uv)  # ORB kept them, so they are inside its border
    dist = hamming(d, desc[lvl0][idx])
    assert np.mean(dist == 0) > 0.95 and np.median(dist) == 0


def test_centroid_angle_brute_force_and_rotation() -> None:
    img = _texture(seed=1)
    rng = np.random.default_rng(2)
    uv = rng.uniform(40, 200, (50, 2))
    # brute force over the disc of radius 15 (ORB's umax, for these radii the plain disc)
    c = np.rint(uv).astype(int)
    du, dv = np.meshgrid(np.arange(-15, 16), np.arange(-15, 16))
    disc = du**2 + dv**2 <= 15.5**2
    ref = []
    for x, y in c:
        patch = img[y - 15 : y + 16, x - 15 : x + 16].astype(float)
        ref.append(np.degrees(np.arctan2((dv * patch)[disc].sum(), (du * patch)[disc].sum())) % 360)
    diff = (centroid_angles_deg(img, uv) - np.array(ref) + 180) % 360 - 180
    assert np.median(np.abs(diff)) < 1.0
    # rotating the image by 90 degrees (clockwise in pixel axes) adds 90 degrees
    rot = np.ascontiguousarray(np.rot90(img, k=-1))
    h = img.shape[0]
    uv_rot = np.column_stack([h - 1 - c[:, 1], c[:, 0]]).astype(float)
    d90 = (centroid_angles_deg(rot, uv_rot) - centroid_angles_deg(img, uv) - 90 + 180) % 360 - 180
    assert np.max(np.abs(d90)) < 1e-6


def test_descriptor_at_the_edge_margin_does_not_see_the_border() -> None:
    """A pixel EDGE_PX from the image edge gets the descriptor it has in a larger image (ORB pads
    by reflection: a smaller margin would let the reflection into the descriptor)."""
    img = _texture(300, 400, seed=3)
    rng = np.random.default_rng(9)
    uv = np.column_stack([rng.integers(150, 250, 60), rng.integers(60, 240, 60)]).astype(float)
    _, full = describe_at(img, uv)
    for i, (x, y) in enumerate(uv):
        x0 = int(x) - EDGE_PX  # crop: the pixel is EDGE_PX from the crop's left edge
        for crop, p in ((img[:, x0:], [EDGE_PX, y]), (img[:, : int(x) + EDGE_PX + 1], [x, y])):
            idx, d = describe_at(np.ascontiguousarray(crop), np.array([p], dtype=float))
            assert idx.tolist() == [0] and np.array_equal(d[0], full[i])


def test_describe_at_drops_border_and_nan_and_checks_input() -> None:
    img = _texture()
    uv = np.array([[5.0, 100.0], [160.0, 120.0], [np.nan, 50.0], [300.0, 230.0], [100.0, 60.0]])
    idx, d = describe_at(img, uv)
    assert idx.tolist() == [1, 4] and d.shape == (2, 32) and d.dtype == np.uint8
    idx, d = describe_at(img, np.zeros((0, 2)))
    assert len(idx) == 0 and d.shape == (0, 32)
    with pytest.raises(ShapeError):
        describe_at(img.astype(np.float32), uv)
    with pytest.raises(ShapeError):
        describe_at(img, uv[:, :1])


def test_hamming_against_unpackbits() -> None:
    rng = np.random.default_rng(3)
    a = rng.integers(0, 256, (7, 32), dtype=np.uint8)
    b = rng.integers(0, 256, (5, 32), dtype=np.uint8)
    ref = np.unpackbits(a[:, None, :] ^ b[None, :, :], axis=2).sum(axis=2)
    np.testing.assert_array_equal(hamming_matrix(a, b), ref)
    np.testing.assert_array_equal(hamming(a[:5], b), np.diag(ref[:5]))


def test_detect_orb_spreads_features_and_is_deterministic() -> None:
    img = _texture(376, 1241, seed=4)
    f = detect_orb(img, 800)
    assert 700 <= len(f) <= 800
    assert f.descriptors.shape == (len(f), 32) and f.octave.min() >= 0
    cells = np.unique((f.uv[:, 1] // 64).astype(int) * 100 + (f.uv[:, 0] // 64).astype(int))
    assert len(cells) >= 0.8 * 6 * 20  # nearly every 64-px cell of the 6 x 20 grid has one
    g = detect_orb(img, 800)
    np.testing.assert_array_equal(f.uv, g.uv)
    np.testing.assert_array_equal(f.descriptors, g.descriptors)
    empty = detect_orb(np.zeros((100, 100), np.uint8), 100)
    assert len(empty) == 0


# ---------------------------------------------------------------------------------------------
# Vocabulary
# ---------------------------------------------------------------------------------------------


def _clusters(n_clusters: int, per: int, flips: int, seed: int) -> tuple[U8, NDArray[np.int64]]:
    """Descriptors around random centres, ``flips`` random bits flipped in each."""
    rng = np.random.default_rng(seed)
    centres = np.unpackbits(rng.integers(0, 256, (n_clusters, 32), dtype=np.uint8), axis=1)
    label = np.repeat(np.arange(n_clusters), per)
    bits = centres[label].copy()
    for row in bits:
        row[rng.choice(256, flips, replace=False)] ^= 1
    return np.packbits(bits, axis=1), label


def test_k_majority_recovers_clusters() -> None:
    desc, label = _clusters(8, 40, 20, seed=5)
    centres = k_majority(desc, 8, np.random.default_rng(0))
    assign = np.argmin(hamming_matrix(desc, centres), axis=1)
    # each true cluster lands in one centre, and different clusters in different centres
    for c in range(8):
        assert len(np.unique(assign[label == c])) == 1
    assert len(np.unique(assign)) == 8


def test_majority_is_the_bitwise_vote_of_each_label() -> None:
    """Against a vote counted bit by bit; labels 3 and 5 have no member (zeros), and a 2-2 tie
    gives 0."""
    rng = np.random.default_rng(3)
    bits = rng.integers(0, 2, (61, 256), dtype=np.uint8)
    label = rng.choice(np.array([0, 1, 2, 4, 6]), 61).astype(np.int64)
    label[:4], bits[:4, 0] = 7, [1, 1, 0, 0]  # label 7: these four rows only, a 2-2 tie at bit 0
    want = np.zeros((8, 256), dtype=np.uint8)
    for k in range(8):
        rows = bits[label == k]
        for b in range(256):
            want[k, b] = 1 if 2 * int(rows[:, b].sum()) > len(rows) else 0
    assert want[7, 0] == 0 and not want[3].any() and not want[5].any()
    assert np.array_equal(_majority(bits, label, 8), np.packbits(want, axis=1))


def test_vocabulary_training_memory_stays_near_its_input() -> None:
    """Training on the 5000 descriptors a database samples at most (160 KB) peaked at 8.8 MiB:
    an int32 cast of all (5000, 256) unpacked bits at once, and (5000, 32) int64 distances with a
    uint64 temporary as large. Blocked, it stays near 3 MiB."""
    desc = np.random.default_rng(4).integers(0, 256, (5000, 32), dtype=np.uint8)
    tracemalloc.start()
    try:
        Vocabulary.train(desc, branching=32, seed=0)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 5 * 2**20


def test_vocabulary_words_and_bow_scores() -> None:
    desc, label = _clusters(64, 20, 12, seed=6)
    voc = Vocabulary.train(desc, branching=8, seed=0)
    assert voc.n_words == 64
    node, word = voc.quantize(desc)
    assert np.array_equal(node, word // 8)
    # descriptors of one cluster share their word (most clusters get their own)
    same = [len(np.unique(word[label == c])) == 1 for c in range(64)]
    assert np.mean(same) > 0.9
    counts = np.stack([np.bincount(word[label < 32], minlength=64),
                       np.bincount(word[label >= 32], minlength=64)]).astype(np.int32)
    s = bow_scores(word[label < 32], counts, 64)
    assert s[0] == pytest.approx(1.0) and s[1] < 0.2
    again = Vocabulary.train(desc, branching=8, seed=0)
    np.testing.assert_array_equal(again.leaves, voc.leaves)


def test_bow_scores_are_the_l1_tfidf_similarity_whatever_the_chunk() -> None:
    """The scores, computed a chunk of documents at a time (the memory bound of a large
    database), against the formula written out for each document; the chunk does not change a bit."""
    rng = np.random.default_rng(3)
    counts = rng.poisson(0.4, (70, 50)).astype(np.uint16)
    query = rng.integers(0, 50, 30)
    df = np.array([np.sum(counts[:, w] > 0) for w in range(50)])
    idf = np.log(70 / np.maximum(df, 1))
    q = np.bincount(query, minlength=50) * idf
    q = q / q.sum()
    want = [1.0 - 0.5 * np.sum(np.abs(d * idf / np.sum(d * idf) - q)) for d in counts.astype(float)]
    got = {c: bow_scores(query, counts, 50, chunk=c) for c in (1, 7, 32, 1000)}
    np.testing.assert_allclose(got[32], want, rtol=0, atol=1e-12)
    assert all(np.array_equal(g, got[32]) for g in got.values())


# ---------------------------------------------------------------------------------------------
# Configuration and database
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("kw", [{"ratio": 0.0}, {"max_hamming": 300}, {"min_matches": 3},
                                {"min_inliers": 5}, {"pnp_thresh_px": 0.0},
                                {"n_corners": 0, "n_features": 0}, {"max_candidates": 0}, {"recent_candidates": -1}])
def test_reloc_config_rejects_bad_values(kw: dict[str, float]) -> None:
    with pytest.raises(ConfigError):
        RelocConfig(**kw)  # type: ignore[arg-type]


def test_database_add_cap_priority_replace_remove() -> None:
    img = _texture()
    rng = np.random.default_rng(7)
    uv = rng.uniform(EDGE_PX, [320 - EDGE_PX, 240 - EDGE_PX], (200, 2))
    ids = np.arange(1000, 1200)
    prio = np.zeros(200, dtype=bool)
    prio[::4] = True
    db = KeyframeDatabase(max_features=80)
    assert db.add(3, img, uv, ids, priority=prio) == 80
    e = db.entries()[0]
    assert set(ids[prio]) <= set(e.point_ids.tolist())  # the 50 with priority first
    assert e.descriptors.shape == (80, 32) and np.all(np.diff(e.point_ids) > 0)
    assert db.nbytes == 80 * 44 and 3 in db and len(db) == 1
    db.add(3, img, uv[:10], ids[:10])  # replaces keyframe 3
    assert len(db) == 1 and len(db.entries()[0].point_ids) == 10
    db.remove(3)
    db.remove(3)
    assert len(db) == 0 and db.vocabulary() is None
    with pytest.raises(ShapeError):
        db.add(1, img, uv, ids[:5])
    with pytest.raises(ConfigError):
        KeyframeDatabase(max_features=0)
    with pytest.raises(ConfigError):  # a word's count must fit the uint16 histograms
        KeyframeDatabase(max_features=65_536)


def test_recovery_keeps_the_newest_keyframes_of_the_current_map() -> None:
    img = _texture()
    rng = np.random.default_rng(8)
    m = VoMap()
    for k in range(6):
        uv = rng.uniform(EDGE_PX, [320 - EDGE_PX, 240 - EDGE_PX], (60, 2))
        m.add_keyframe(10 * k, np.eye(4), np.arange(100 * k, 100 * k + 60), uv)
    rec = MapRecovery(np.eye(3), RecoveryConfig(max_keyframes=3), seed=0)
    for k in range(6):
        rec.add_keyframe(0, k, img, m)
        assert [e.kf_id for e in rec.dbs[0].entries()] == list(range(max(0, k - 2), k + 1))
    assert sorted(rec.dbs[0].entries()[0].point_ids.tolist())[0] >= 300  # keyframe 3's points
    rec.lost(0)
    assert rec.attempt(img, m, frame=7) is not None  # the lost map is searched
    rec.give_up()
    rec.add_keyframe(1, 0, img, m)  # a new map: its own database, the old one is never searched again
    assert list(rec.dbs) == [1] and len(rec.dbs[1]) == 1
    rec.lost(0)
    assert rec.attempt(img, m, frame=8) is None  # nothing left to search in map 0
    rec.add_keyframe(1, 1, img, m)
    assert list(rec.dbs) == [1] and len(rec.dbs[1]) == 2


# ---------------------------------------------------------------------------------------------
# Relocalisation in the simulator: the room, exact map points from the rendered depth
# ---------------------------------------------------------------------------------------------

CAM = PinholeCamera(640, 480, 400.0, 400.0, 319.5, 239.5)
K = np.array([[400.0, 0.0, 319.5], [0.0, 400.0, 239.5], [0.0, 0.0, 1.0]])
R_FORWARD = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])  # cam z = world x


def _pose(x: float, y: float, z: float, yaw: float, roll: float = 0.0) -> SE3:
    """T_world_cam of a camera at (x, y, z), heading ``yaw`` about world z, rolled about its axis."""
    return (SE3(SO3.exp([0.0, 0.0, yaw]), np.array([x, y, z])) @ SE3(SO3.from_matrix(R_FORWARD), np.zeros(3))
            @ SE3(SO3.exp([0.0, 0.0, roll]), np.zeros(3)))


class _Room:
    def __init__(self) -> None:
        self.renderer = SceneRenderer(make_scene("room", 0), CAM)

    def image(self, T_world_cam: SE3) -> tuple[U8, F64]:
        irr, depth = self.renderer.render(T_world_cam)
        return np.clip(irr * (200.0 / 60.0), 0, 255).astype(np.uint8), depth.astype(np.float64)


@pytest.fixture(scope="module")
def room() -> _Room:
    return _Room()


def _map(room: _Room, poses: list[SE3]) -> tuple[VoMap, KeyframeDatabase]:
    """Keyframes at ``poses`` facing the +x wall; every corner away from depth edges becomes an
    exact map point (track ids unique over the keyframes)."""
    vm, db = VoMap(), KeyframeDatabase()
    det = DetectorConfig(max_corners=1000, quality_level=0.001, min_distance_px=10, block_size=5,
                         border_px=8, grid_rows=6, grid_cols=8)
    next_id = 0
    for T in poses:
        img, depth = room.image(T)
        c = detect_corners(img, det)
        u, v = np.rint(c).astype(int).T
        lo = cv2.erode(depth, np.ones((5, 5)))[v, u]
        hi = cv2.dilate(depth, np.ones((5, 5)))[v, u]
        z = depth[v, u]
        smooth = (hi - lo) < 0.02 * z
        Xc = np.column_stack([(c[:, 0] - K[0, 2]) / K[0, 0], (c[:, 1] - K[1, 2]) / K[1, 1],
                              np.ones(len(c))]) * z[:, None]
        Xw = Xc @ T.R.T + T.t
        ids = np.arange(next_id, next_id + len(c))
        next_id += len(c)
        vm.set_points(ids[smooth], Xw[smooth])
        kf = vm.add_keyframe(len(vm.keyframes), T.inverse().matrix(), ids, c)
        db.add(kf.kf_id, img, c, ids, priority=smooth)
    return vm, db


@pytest.fixture(scope="module")
def room_map(room: _Room) -> tuple[VoMap, KeyframeDatabase]:
    return _map(room, [_pose(-1.0, 0.0, 1.3, 0.0), _pose(-1.0, -0.3, 1.3, 0.05)])


def _errors(res: RelocResult, T_world_cam: SE3) -> tuple[float, float]:
    """Rotation error (deg) and camera position error (m) of an OK result."""
    assert res.T_cam_world is not None
    T_cw = T_world_cam.inverse().matrix()
    dR = res.T_cam_world[:3, :3] @ T_cw[:3, :3].T
    rot = float(np.degrees(np.arccos(np.clip((np.trace(dR) - 1) / 2, -1, 1))))
    centre = -res.T_cam_world[:3, :3].T @ res.T_cam_world[:3, 3]
    return rot, float(np.linalg.norm(centre - T_world_cam.t))


@pytest.mark.parametrize(("T", "what"), [
    (_pose(-0.6, 0.3, 1.4, 0.15, roll=0.4), "0.5 m aside and ahead, yaw 9 deg, roll 23 deg"),
    (_pose(-0.8, 0.0, 1.3, 0.0, roll=np.pi / 2), "camera rolled by 90 deg"),
    (_pose(-2.0, 0.2, 1.3, 0.1), "1 m further back (the scene looks smaller)"),
])
def test_relocalize_recovers_the_true_pose(room: _Room, room_map: tuple[VoMap, KeyframeDatabase],
                                           T: SE3, what: str) -> None:
    vm, db = room_map
    img, _ = room.image(T)
    res = relocalize(img, K, vm, db, seed=0)
    assert res.status is RelocStatus.OK, what
    rot, pos = _errors(res, T)
    assert rot < 0.1 and pos < 0.01, (what, rot, pos)
    assert res.n_inliers == len(res.point_ids) >= 100
    assert res.kf_id in (0, 1) and res.n_matches >= 15
    # the inliers are map points that project onto their pixels under the true pose
    assert np.all(vm.points_of(res.point_ids)) and np.all(np.diff(res.point_ids) > 0)
    uv, z = project(K, T.inverse().matrix(), vm.xyz[res.point_ids])
    err = np.linalg.norm(uv - res.uv, axis=1)
    assert np.all(z > 0) and np.median(err) < 1.0 and np.percentile(err, 95) < 3.0


def test_relocalize_other_place_noise_black_give_a_status(
        room: _Room, room_map: tuple[VoMap, KeyframeDatabase]) -> None:
    vm, db = room_map
    other, _ = room.image(_pose(0.0, 0.0, 1.3, np.pi))  # the opposite (-x) wall
    res = relocalize(other, K, vm, db, seed=0)
    assert res.status in (RelocStatus.TOO_FEW_MATCHES, RelocStatus.PNP_FAILED)
    assert res.T_cam_world is None and len(res.point_ids) == 0 and res.kf_id is None
    noise = np.random.default_rng(8).integers(0, 256, (480, 640), dtype=np.uint8)
    res = relocalize(noise, K, vm, db, seed=0)
    assert res.status in (RelocStatus.TOO_FEW_MATCHES, RelocStatus.PNP_FAILED)
    black = relocalize(np.zeros((480, 640), np.uint8), K, vm, db, seed=0)
    assert black.status is RelocStatus.NO_FEATURES and black.n_features == 0
    # an empty database, and a map whose points were all removed: nothing to search
    assert relocalize(other, K, vm, KeyframeDatabase(), seed=0).status is RelocStatus.NO_CANDIDATE
    gone = VoMap(list(vm.keyframes))  # the same keyframes, no point
    assert relocalize(other, K, gone, db, seed=0).status is RelocStatus.NO_CANDIDATE
    with pytest.raises(ShapeError):
        relocalize(other.astype(np.float32), K, vm, db)
    with pytest.raises(ShapeError):
        relocalize(other, K[:2], vm, db)


def test_relocalize_is_deterministic_and_features_can_be_precomputed(
        room: _Room, room_map: tuple[VoMap, KeyframeDatabase]) -> None:
    T = _pose(-0.6, 0.3, 1.4, 0.15, roll=0.4)
    img, _ = room.image(T)
    vm, db = room_map
    a = relocalize(img, K, vm, db, seed=3)
    vm2, db2 = _map(room, [_pose(-1.0, 0.0, 1.3, 0.0), _pose(-1.0, -0.3, 1.3, 0.05)])
    b = relocalize(img, K, vm2, db2, seed=3)
    feats = describe_query(img, RelocConfig())
    c = relocalize(feats, K, vm, db, seed=3, image_shape_hw=img.shape)
    for r in (b, c):
        assert r.status is a.status is RelocStatus.OK and r.kf_id == a.kf_id
        assert a.T_cam_world is not None and r.T_cam_world is not None
        np.testing.assert_array_equal(r.T_cam_world, a.T_cam_world)
        np.testing.assert_array_equal(r.point_ids, a.point_ids)
        np.testing.assert_array_equal(r.uv, a.uv)
    with pytest.raises(ShapeError):
        relocalize(feats, K, vm, db)
