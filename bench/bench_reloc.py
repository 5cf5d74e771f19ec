"""Relocalisation timings on KITTI 00 images (1241 x 376), one thread, one core.

Figures (medians over repeats): the keyframe insertion (ORB at ~1500 tracked corners), one
relocalisation attempt that succeeds (frame 5 in a ground-truth map of keyframes 0, 2, 4) and one
that misses (frame 190), the parts of an attempt, the vocabulary training, and the keyframe
ranking against database size: bag of words (what relocalize uses) against brute-force ratio
matching of the query to every keyframe (what it would cost without the vocabulary).

Run alone: ``.venv/bin/python -m bench.bench_reloc [--quick]``.
"""

from __future__ import annotations

import os
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray
from threadpoolctl import threadpool_limits

from amrvio.estimator.keyframe_db import KeyframeDatabase
from amrvio.estimator.relocalizer import RelocConfig, describe_query, relocalize
from amrvio.estimator.vo_map import VoMap
from amrvio.geometry.projection import pixels_to_normalized
from amrvio.geometry.triangulation import triangulate
from amrvio.io.dataset import open_dataset
from amrvio.tracking.vocabulary import Vocabulary
from amrvio.types.lie import se3_matrix_inverse

F64 = NDArray[np.float64]
U8 = NDArray[np.uint8]
Row = dict[str, object]

KITTI = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "kitti00_0000-0199"


def _row(name: str, value: float | tuple[float, float], unit: str, note: str = "") -> Row:
    """A figure; a (wall, cpu) pair of times gives the wall median and the CPU one in the note
    (on a shared machine the CPU time is the steadier of the two)."""
    if isinstance(value, tuple):
        wall, cpu = value
        note = f"cpu {cpu:.1f} ms; {note}" if note else f"cpu {cpu:.1f} ms"
        value = wall
    return {"name": name, "value": value, "unit": unit, "note": note}


def _median_ms(f: Callable[[], object], repeats: int) -> tuple[float, float]:
    """Median wall and process CPU milliseconds of ``f()`` over ``repeats`` calls."""
    wall, cpu = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        f()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return 1e3 * statistics.median(wall), 1e3 * statistics.median(cpu)


def _corners(img: U8) -> F64:
    """The tracker's budget: 1500 Shi-Tomasi corners 10 px apart."""
    return cv2.goodFeaturesToTrack(img, 1500, 0.001, 10, blockSize=5).reshape(-1, 2).astype(np.float64)


def _gt_map(ds: object, imgs: dict[int, U8], K: F64, T_world_cam: F64) -> tuple[VoMap, KeyframeDatabase]:
    """Keyframes 0, 2, 4 with GT poses; KLT tracks from frame 0 triangulated between 0 and 4."""
    p0 = _corners(imgs[0])
    ids = np.arange(len(p0))
    p = p0.astype(np.float32)
    ok = np.ones(len(p0), dtype=bool)
    pts, alive = {0: p0}, {0: ok.copy()}
    for i in range(1, 5):
        p1, st, _ = cv2.calcOpticalFlowPyrLK(imgs[i - 1], imgs[i], p, None, winSize=(21, 21), maxLevel=3)
        ok &= st.ravel() == 1
        p = p1
        pts[i], alive[i] = p.astype(np.float64), ok.copy()
    T_cw = {i: se3_matrix_inverse(T_world_cam[i]) for i in (0, 2, 4)}
    tri = triangulate(T_cw[0], T_cw[4], pixels_to_normalized(pts[0], K), pixels_to_normalized(pts[4], K),
                      min_parallax_deg=0.5, max_reproj_px=2.0, focal_px=float(K[0, 0]))
    vm, db = VoMap(), KeyframeDatabase()
    good = tri.valid & alive[4]
    vm.set_points(ids[good], tri.points_world[good])
    for k in (0, 2, 4):
        s = alive[k]
        kf = vm.add_keyframe(k, T_cw[k], ids[s], pts[k][s])
        db.add(kf.kf_id, imgs[k], pts[k][s], ids[s], priority=vm.points_of(ids[s]))
    return vm, db


def _brute_force_rank(q: U8, entries: list[U8]) -> list[int]:
    """Ratio-test match counts of the query against every keyframe (cv2.BFMatcher, Hamming)."""
    bf = cv2.BFMatcher(cv2.NORM_HAMMING)
    counts = []
    for d in entries:
        n = 0
        for m in bf.knnMatch(q, d, k=2):
            if len(m) == 2 and m[0].distance <= 50 and m[0].distance < 0.75 * m[1].distance:
                n += 1
        counts.append(n)
    return counts


def _bow_ranking(db: KeyframeDatabase, vocab: Vocabulary, q: U8) -> Callable[[], object]:
    return lambda: db.rank(vocab.quantize(q)[1])


def _bf_ranking(q: U8, descs: list[U8]) -> Callable[[], object]:
    return lambda: _brute_force_rank(q, descs)


def run(quick: bool) -> list[Row]:
    if not KITTI.is_dir():
        raise FileNotFoundError(f"{KITTI} missing (../shared/data)")
    repeats = 3 if quick else 10
    pinned = hasattr(os, "sched_setaffinity")
    old_aff = os.sched_getaffinity(0) if pinned else set()
    old_threads = cv2.getNumThreads()
    rows: list[Row] = []
    try:
        if pinned:
            os.sched_setaffinity(0, {min(old_aff)})
        cv2.setNumThreads(1)
        with threadpool_limits(1):
            ds = open_dataset(f"kitti:{KITTI}")
            cam, gt = ds.camera, ds.groundtruth
            if cam is None or gt is None:
                raise RuntimeError("KITTI reader gave no camera or ground truth")
            K = np.array([[cam.fx, 0.0, cam.cx], [0.0, cam.fy, cam.cy], [0.0, 0.0, 1.0]])
            imgs = {i: ds.frames[i].load() for i in (0, 1, 2, 3, 4, 5, 190)}
            vm, db = _gt_map(ds, imgs, K, gt.matrices())
            c0 = _corners(imgs[0])
            ids0 = np.arange(len(c0))
            scratch = KeyframeDatabase()
            rows.append(_row("keyframe insertion (db.add)", _median_ms(
                lambda: scratch.add(0, imgs[0], c0, ids0), repeats), "ms",
                f"ORB at {len(c0)} tracked corners, 1241 x 376"))
            rows.append(_row("database memory per keyframe", scratch.nbytes / 1024, "KiB",
                             f"{scratch.n_descriptors} descriptors x 44 B"))
            cfg = RelocConfig()
            ok = relocalize(imgs[5], K, vm, db, cfg)  # trains the vocabulary once
            miss = relocalize(imgs[190], K, vm, db, cfg)
            rows.append(_row("relocalize, success (frame 5, 3 keyframes)", _median_ms(
                lambda: relocalize(imgs[5], K, vm, db, cfg), repeats), "ms",
                f"{ok.status.value}, {ok.n_inliers} inliers"))
            rows.append(_row("relocalize, miss (frame 190)", _median_ms(
                lambda: relocalize(imgs[190], K, vm, db, cfg), repeats), "ms", miss.status.value))
            rows.append(_row("  of which describe_query", _median_ms(
                lambda: describe_query(imgs[5], cfg), repeats), "ms",
                f"{cfg.n_corners} corners + {cfg.n_features} ORB"))
            corners_only = RelocConfig(n_features=0)
            rows.append(_row("relocalize, success, corners only (n_features=0)", _median_ms(
                lambda: relocalize(imgs[5], K, vm, db, corners_only), repeats), "ms",
                f"{relocalize(imgs[5], K, vm, db, corners_only).n_inliers} inliers"))
            # ranking against database size: keyframes every 2nd frame of KITTI 00
            q = describe_query(imgs[5], cfg)
            n_max = 50 if quick else 100
            frames = [ds.frames[2 * k].load() for k in range(n_max)]
            kf_corners = [_corners(img) for img in frames]
            big = KeyframeDatabase()
            for k in range(n_max):
                big.add(k, frames[k], kf_corners[k], np.arange(len(kf_corners[k])) + 10_000 * k)
            sample = np.concatenate([e.descriptors for e in big.entries()])[:5_000]
            rows.append(_row("vocabulary training (5000 descriptors)", _median_ms(
                lambda: Vocabulary.train(sample, 32, 0), max(1, repeats // 3)), "ms", "2 levels of 32"))
            for n in (10, 50, 100)[: 2 if quick else 3]:
                sub = KeyframeDatabase()
                for k in range(n):
                    sub.add(k, frames[k], kf_corners[k], np.arange(len(kf_corners[k])) + 10_000 * k)
                vocab = sub.vocabulary()
                if vocab is None:
                    raise RuntimeError("empty keyframe database")
                rows.append(_row(f"rank {n} keyframes, bag of words", _median_ms(
                    _bow_ranking(sub, vocab, q.descriptors), repeats),
                    "ms", "quantize the query + tf-idf L1 scores"))
                descs = [e.descriptors for e in sub.entries()]
                rows.append(_row(f"rank {n} keyframes, brute-force ratio matching", _median_ms(
                    _bf_ranking(q.descriptors, descs), max(1, repeats // 3)),
                    "ms", f"{len(q)} query descriptors vs each keyframe"))
    finally:
        cv2.setNumThreads(old_threads)
        if pinned:
            os.sched_setaffinity(0, old_aff)
    return rows


if __name__ == "__main__":
    for r in run("--quick" in sys.argv):
        v = r["value"]
        print(f"{r['name']:52s} {v:9.2f} {r['unit']:4s} {r['note']}" if isinstance(v, float)
              else f"{r['name']:52s} {v} {r['unit']} {r['note']}")
