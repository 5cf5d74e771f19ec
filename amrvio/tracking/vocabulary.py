"""A small vocabulary of binary descriptors: a two-level k-majority tree (the binary k-means of
DBoW2, Galvez-Lopez and Tardos 2012), and the tf-idf L1 score of bags of words.

Words are the leaves, ``word = node * branching + leaf``; the first-level ``node`` of a descriptor
also serves to restrict descriptor matching to descriptors of the same node.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ShapeError
from amrvio.tracking.orb import hamming_matrix

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]
U8 = NDArray[np.uint8]


def _nearest(desc: U8, centers: U8) -> I64:
    """Index of the nearest center (Hamming; the lowest index on ties) of each descriptor, for
    1024 descriptors at a time (their distance rows only)."""
    out = np.zeros(len(desc), dtype=np.int64)
    for lo in range(0, len(desc), 1024):
        out[lo:lo + 1024] = np.argmin(hamming_matrix(desc[lo:lo + 1024], centers), axis=1)
    return out


def _majority(bits: NDArray[np.uint8], label: I64, k: int) -> U8:
    """(k, 32) bitwise majority of the (N, 256) unpacked bits per label (ties -> 0; a label
    without members gets zeros). Summed one label at a time: a reduction over all N rows at once
    (``np.add.reduceat`` with an int32 result) casts the whole (N, 256) input first, 5 MiB for the
    5000 descriptors a vocabulary trains on."""
    n = np.bincount(label, minlength=k)[:k]
    counts = np.zeros((k, bits.shape[1]), dtype=np.int64)
    for i in np.flatnonzero(n):
        counts[i] = bits[label == i].sum(axis=0, dtype=np.int64)
    return np.packbits(2 * counts > n[:, None], axis=1)


def k_majority(desc: U8, k: int, rng: np.random.Generator, iterations: int = 8) -> U8:
    """At most ``k`` (K, 32) centers of the (N, 32) descriptors: greedy k-means++ seeding (Arthur
    and Vassilvitskii 2007) with Hamming distances, then Lloyd iterations with bitwise-majority
    centers (a center left without members is dropped). Fewer than ``k`` distinct descriptors give
    fewer centers."""
    if len(desc) <= k:
        uniq = np.unique(desc, axis=0)
        if len(uniq) <= k:
            return uniq
    centers = [int(rng.integers(len(desc)))]
    dmin = hamming_matrix(desc, desc[centers])[:, 0].astype(np.float64)
    trials = 2 + int(np.log(k))  # greedy k-means++: the best of a few draws (as scikit-learn)
    while len(centers) < k:
        w = dmin**2
        if w.sum() <= 0:
            break
        cand = rng.choice(len(desc), size=trials, p=w / w.sum())
        d_new = np.minimum(dmin[:, None], hamming_matrix(desc, desc[cand]).astype(np.float64))
        best = int(np.argmin((d_new**2).sum(axis=0)))
        centers.append(int(cand[best]))
        dmin = d_new[:, best]
    c = desc[centers].copy()
    bits = np.unpackbits(desc, axis=1)
    for _ in range(iterations):
        label = _nearest(desc, c)
        used = np.unique(label)
        new = _majority(bits, label, len(c))[used]
        if new.shape == c.shape and np.array_equal(new, c):
            break
        c = new
    return c


@dataclass(frozen=True, slots=True)
class Vocabulary:
    """Two-level tree: ``top`` (B1, 32) first-level centers, ``leaves`` (B1, B, 32) the leaf
    centers under each (rows past ``n_leaves[i]`` unused). ``n_words = B1 * B``."""

    top: U8
    leaves: U8
    n_leaves: I64

    @property
    def branching(self) -> int:
        return int(self.leaves.shape[1])

    @property
    def n_words(self) -> int:
        return int(self.leaves.shape[0] * self.leaves.shape[1])

    @staticmethod
    def train(desc: U8, branching: int = 32, seed: int = 0) -> Vocabulary:
        """Train on (N, 32) uint8 descriptors (N >= 1)."""
        if desc.ndim != 2 or desc.dtype != np.uint8 or len(desc) == 0:
            raise ShapeError(f"Vocabulary.train: (N, 32) uint8 descriptors, got {desc.shape} {desc.dtype}")
        rng = np.random.default_rng(seed)
        top = k_majority(desc, branching, rng)
        node = _nearest(desc, top)
        leaves = np.zeros((len(top), branching, desc.shape[1]), dtype=np.uint8)
        n_leaves = np.zeros(len(top), dtype=np.int64)
        for i in range(len(top)):
            c = k_majority(desc[node == i], branching, rng) if np.any(node == i) else top[i : i + 1]
            leaves[i, : len(c)] = c
            n_leaves[i] = len(c)
        return Vocabulary(top, leaves, n_leaves)

    def quantize(self, desc: U8) -> tuple[I64, I64]:
        """(N,) first-level node and (N,) word of each (N, 32) descriptor."""
        node = _nearest(desc, self.top) if len(desc) else np.zeros(0, dtype=np.int64)
        word = np.zeros(len(desc), dtype=np.int64)
        for i in np.unique(node):
            sel = np.flatnonzero(node == i)
            word[sel] = i * self.branching + _nearest(desc[sel], self.leaves[i, : self.n_leaves[i]])
        return node, word


def bow_scores(query_words: I64, doc_counts: NDArray[np.integer], n_words: int, chunk: int = 32) -> F64:
    """DBoW2 L1 similarity in [0, 1] of a query to each document: ``1 - |v_q - v_d|_1 / 2`` with
    tf-idf vectors normalised to unit L1 norm; ``doc_counts`` (D, n_words) word counts per
    document; idf = log(D / documents containing the word). The documents are scored ``chunk``
    at a time (each row on its own, so the scores do not depend on it): the memory it takes stays
    that of ``chunk`` float vectors however large the database."""
    counts = np.asarray(doc_counts)
    n_docs = len(counts)
    if n_docs == 0:
        return np.zeros(0)
    df = np.count_nonzero(counts, axis=0)
    idf = np.log(n_docs / np.maximum(df, 1))
    vq = np.bincount(query_words, minlength=n_words).astype(np.float64) * idf
    vq /= max(float(vq.sum()), 1e-300)
    scores: F64 = np.empty(n_docs)
    step = max(int(chunk), 1)
    for lo in range(0, n_docs, step):
        vd = counts[lo:lo + step].astype(np.float64) * idf
        vd /= np.maximum(vd.sum(axis=1, keepdims=True), 1e-300)
        scores[lo:lo + step] = 1.0 - 0.5 * np.abs(vd - vq[None, :]).sum(axis=1)
    return scores


__all__ = ["Vocabulary", "bow_scores", "k_majority"]
