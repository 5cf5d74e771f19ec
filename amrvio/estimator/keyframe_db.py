"""The keyframe database of relocalisation: ORB descriptors at each keyframe's tracked pixels,
with the track ids (= map point ids of :class:`~amrvio.estimator.vo_map.VoMap`) they belong to,
and a bag-of-words index (:mod:`amrvio.tracking.vocabulary`) that ranks the keyframes against a
query image. Used by :mod:`amrvio.estimator.relocalizer`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ConfigError, ShapeError
from amrvio.tracking.orb import describe_at
from amrvio.tracking.vocabulary import Vocabulary, bow_scores

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]
I32 = NDArray[np.int32]
U8 = NDArray[np.uint8]


@dataclass(frozen=True, slots=True)
class KeyframeEntry:
    """What the database keeps of a keyframe: (M, 32) uint8 ORB ``descriptors`` at the tracked
    pixels and the (M,) track ids (map point ids) they belong to."""

    kf_id: int
    descriptors: U8
    point_ids: I64


VOCABULARY_BRANCHING = 32
"""Two levels of 32: 1024 words."""
VOCABULARY_TRAIN_MAX = 5_000
"""Descriptors the vocabulary is trained on at most (sampled evenly over the keyframes)."""


class KeyframeDatabase:
    """ORB descriptors of the keyframes of one map, by keyframe id, and the bag-of-words index
    that ranks them. ``max_features``: descriptors kept per keyframe (each with its 8-byte id and
    4-byte word: 44 bytes). The vocabulary is trained on the database's own descriptors when a ranking
    is first asked for, and again whenever the number of descriptors has doubled since."""

    def __init__(self, max_features: int = 1500, seed: int = 0) -> None:
        if not 1 <= max_features <= 65_535:  # the word counts are uint16
            raise ConfigError(f"KeyframeDatabase: max_features must be in [1, 65535], got {max_features}")
        self.max_features = max_features
        self.seed = seed
        self._entries: dict[int, KeyframeEntry] = {}
        self._vocab: Vocabulary | None = None
        self._trained_with = 0
        self._words: dict[int, I32] = {}
        self._counts: NDArray[np.uint16] | None = None  # (D, n_words) cache of the histograms

    def __len__(self) -> int:
        return len(self._entries)

    def __contains__(self, kf_id: int) -> bool:
        return kf_id in self._entries

    @property
    def n_descriptors(self) -> int:
        return sum(len(e.point_ids) for e in self._entries.values())

    @property
    def nbytes(self) -> int:
        """Bytes held by the descriptors, ids and words (the vocabulary adds 33 KiB)."""
        return sum(e.descriptors.nbytes + e.point_ids.nbytes + 4 * len(e.point_ids)
                   for e in self._entries.values())

    def entries(self) -> list[KeyframeEntry]:
        """The entries in insertion order."""
        return list(self._entries.values())

    def add(self, kf_id: int, image: U8, uv: F64, point_ids: I64,
            priority: NDArray[np.bool_] | None = None) -> int:
        """Describe keyframe ``kf_id``: ORB at the (M, 2) pixels ``uv`` of the undistorted (H, W)
        uint8 ``image``, for the (M,) track ids ``point_ids``. At most ``max_features`` are
        kept: first those where the (M,) ``priority`` is true (e.g. the tracks that already
        have a map point), then the rest, each spread evenly over the input order. Re-adding a
        ``kf_id`` replaces it. Returns the number of descriptors stored."""
        uv = np.asarray(uv, dtype=np.float64)
        ids = np.asarray(point_ids, dtype=np.int64)
        if uv.ndim != 2 or uv.shape[1] != 2 or ids.shape != (len(uv),):
            raise ShapeError(f"KeyframeDatabase.add: uv {uv.shape} and point_ids {ids.shape} "
                             "must be (M, 2) and (M,)")
        if priority is not None and np.shape(priority) != (len(uv),):
            raise ShapeError(f"KeyframeDatabase.add: priority {np.shape(priority)} for {len(uv)} pixels")
        kept, desc = describe_at(image, uv)
        cap = self.max_features
        if len(kept) > cap:
            first = np.ones(len(kept), dtype=bool) if priority is None else \
                np.asarray(priority, dtype=bool)[kept]
            pick = _spread(np.flatnonzero(first), cap)
            pick = np.sort(np.concatenate([pick, _spread(np.flatnonzero(~first), cap - len(pick))]))
            kept, desc = kept[pick], desc[pick]
        self._entries.pop(kf_id, None)
        self._entries[kf_id] = KeyframeEntry(kf_id, np.ascontiguousarray(desc), ids[kept].copy())
        if self._vocab is not None:
            self._words[kf_id] = self._vocab.quantize(desc)[1].astype(np.int32)
        self._counts = None
        return len(kept)

    def remove(self, kf_id: int) -> None:
        """Forget keyframe ``kf_id`` (no-op when absent)."""
        if self._entries.pop(kf_id, None) is not None:
            self._words.pop(kf_id, None)
            self._counts = None

    def vocabulary(self) -> Vocabulary | None:
        """The vocabulary, (re)trained when missing or when the descriptors doubled; None while
        the database holds no descriptor."""
        n = self.n_descriptors
        if n == 0:
            return None
        if self._vocab is None or n > 2 * self._trained_with:
            per = max(1, VOCABULARY_TRAIN_MAX // len(self._entries))
            sample = np.concatenate([e.descriptors[_spread(np.arange(len(e.descriptors)), per)]
                                     for e in self._entries.values()])
            self._vocab = Vocabulary.train(sample, VOCABULARY_BRANCHING, self.seed)
            self._trained_with = n
            self._words = {k: self._vocab.quantize(e.descriptors)[1].astype(np.int32)
                           for k, e in self._entries.items()}
            self._counts = None
        return self._vocab

    def words(self, kf_id: int) -> I32:
        """(M,) vocabulary words of the descriptors of keyframe ``kf_id`` (trains the
        vocabulary if needed)."""
        if self.vocabulary() is None or kf_id not in self._words:
            raise KeyError(f"keyframe {kf_id} is not in the database")
        return self._words[kf_id]

    def rank(self, query_words: I64) -> list[tuple[float, KeyframeEntry]]:
        """All entries with their bag-of-words score (tf-idf L1, in [0, 1]) against the query's
        (N,) vocabulary words (:meth:`Vocabulary.quantize` of its descriptors), best first (ties:
        earlier insertion first)."""
        vocab = self.vocabulary()
        if vocab is None:
            return []
        entries = self.entries()
        if self._counts is None:
            self._counts = np.stack([np.bincount(self._words[e.kf_id], minlength=vocab.n_words)
                                     for e in entries]).astype(np.uint16)  # < max_features <= 65 535 a word
        scores = bow_scores(query_words, self._counts, vocab.n_words)
        order = np.lexsort((np.arange(len(entries)), -scores))
        return [(float(scores[i]), entries[i]) for i in order]


def _spread(idx: NDArray[np.intp], n: int) -> NDArray[np.intp]:
    """At most ``n`` of ``idx``, evenly spaced."""
    if n <= 0:
        return idx[:0]
    if len(idx) <= n:
        return idx
    return idx[np.linspace(0, len(idx) - 1, n).round().astype(np.intp)]


__all__ = ["VOCABULARY_BRANCHING", "VOCABULARY_TRAIN_MAX", "KeyframeDatabase", "KeyframeEntry"]
