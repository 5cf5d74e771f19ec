"""Poses by frame index in one growing array: what a long run keeps of every frame's pose.

A dict of 4x4 arrays costs about 330 bytes a frame (the array object, its header and the dict's
entry); a :class:`PoseBook` costs 129 (the 16 numbers and a flag), and its arrays grow by
doubling.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]


class PoseBook:
    """4x4 poses by frame index (>= 0): ``book[i] = T``, ``book[i]`` (a copy; KeyError when
    frame ``i`` has none), ``i in book``, ``len(book)``, and iteration over the indices that
    have a pose, increasing (:meth:`items` with the poses)."""

    def __init__(self) -> None:
        self._T = np.zeros((0, 4, 4))
        self._has = np.zeros(0, dtype=bool)
        self._n = 0

    def __setitem__(self, i: int, T: F64) -> None:
        if i < 0:
            raise KeyError(f"PoseBook: frame index {i} < 0")
        if i >= len(self._has):
            cap = max(i + 1, 2 * len(self._has), 256)
            T_all, has = np.zeros((cap, 4, 4)), np.zeros(cap, dtype=bool)
            T_all[: len(self._T)] = self._T
            has[: len(self._has)] = self._has
            self._T, self._has = T_all, has
        self._T[i] = T
        if not self._has[i]:
            self._has[i] = True
            self._n += 1

    def __getitem__(self, i: int) -> F64:
        if i not in self:
            raise KeyError(i)
        return self._T[i].copy()

    def __contains__(self, i: object) -> bool:
        return isinstance(i, int | np.integer) and 0 <= int(i) < len(self._has) and bool(self._has[int(i)])

    def __len__(self) -> int:
        return self._n

    def __iter__(self) -> Iterator[int]:
        return (int(i) for i in np.flatnonzero(self._has))

    def items(self) -> Iterator[tuple[int, F64]]:
        return ((i, self._T[i].copy()) for i in self)


__all__ = ["PoseBook"]
