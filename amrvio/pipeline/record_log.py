"""The frame records of a run, kept on disk as the run goes so that its memory stays flat.

A :class:`RecordLog` is a read-only sequence of :class:`~amrvio.pipeline.records.FrameRecord`
(index, slice, iterate, ``len``, compare with another sequence). Each record appended is pickled
into an anonymous temporary file, which the system removes when the log is closed or collected
and when the process ends, however it ends. Where no temporary file can be made, the pickles stay
in memory, with a warning. The newest ``keep`` records also stay in memory, because the pipeline
looks back at recent frames. Reading an older record unpickles a copy of it: equal to the record
appended, not the same object.

A record costs some kilobytes in memory (its reports, diagnostics and poses) and about three on
disk; a long recording holds hundreds of thousands of them.
"""

from __future__ import annotations

import dataclasses
import io
import logging
import math
import pickle
import tempfile
from array import array
from collections import deque
from collections.abc import Iterable, Iterator, Sequence
from typing import IO, overload

import numpy as np

from amrvio.pipeline.records import FrameRecord

log = logging.getLogger(__name__)

KEEP_IN_MEMORY = 64
"""Records kept in memory, the newest: the pipeline's look-back (repeated frames, the last tracked
frame before a loss) reads those; older ones come from the file."""


class RecordLog(Sequence[FrameRecord]):
    """Append-only frame records, the newest ``keep`` in memory, every one in a temporary file
    (in ``directory``, default the system's temporary folder)."""

    def __init__(self, records: Iterable[FrameRecord] = (), *, keep: int = KEEP_IN_MEMORY,
                 directory: str | None = None) -> None:
        if keep < 1:
            raise ValueError(f"RecordLog: keep must be >= 1, got {keep}")
        try:
            self._fh: IO[bytes] = tempfile.TemporaryFile(prefix="amrvio-records-", dir=directory)
        except OSError as exc:  # no writable temporary folder: the records stay in memory, pickled
            log.warning("frame records kept in memory: cannot create a file in %s (%s)",
                        directory or tempfile.gettempdir(), exc.strerror or exc)
            self._fh = io.BytesIO()
        self._starts = array("q")  # where each pickled record starts in the file (8 bytes a record)
        self._recent: deque[FrameRecord] = deque(maxlen=keep)
        self._end = 0
        for rec in records:
            self.append(rec)

    def append(self, rec: FrameRecord) -> None:
        blob = pickle.dumps(rec, protocol=pickle.HIGHEST_PROTOCOL)
        self._fh.seek(self._end)
        self._fh.write(blob)
        self._starts.append(self._end)
        self._end += len(blob)
        self._recent.append(rec)

    def close(self) -> None:
        """Remove the file (the records kept in memory stay readable; older ones no longer)."""
        self._fh.close()

    def __len__(self) -> int:
        return len(self._starts)

    def _load(self, i: int) -> FrameRecord:
        n_old = len(self._starts) - len(self._recent)
        if i >= n_old:
            return self._recent[i - n_old]
        off = self._starts[i]
        self._fh.seek(off)
        rec = pickle.loads(self._fh.read(self._starts[i + 1] - off))  # an old record is never the last
        if not isinstance(rec, FrameRecord):
            raise TypeError(f"RecordLog: entry {i} is a {type(rec).__name__}, not a FrameRecord")
        return rec

    @overload
    def __getitem__(self, i: int) -> FrameRecord: ...

    @overload
    def __getitem__(self, i: slice) -> list[FrameRecord]: ...

    def __getitem__(self, i: int | slice) -> FrameRecord | list[FrameRecord]:
        if isinstance(i, slice):
            return [self._load(k) for k in range(*i.indices(len(self)))]
        n = len(self._starts)
        k = int(i) + n if int(i) < 0 else int(i)
        if not 0 <= k < n:
            raise IndexError(f"RecordLog index {i} out of range for {n} records")
        return self._load(k)

    def __iter__(self) -> Iterator[FrameRecord]:
        for k in range(len(self._starts)):
            yield self._load(k)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Sequence) or len(other) != len(self):
            return NotImplemented if not isinstance(other, Sequence) else False
        return all(_same(a, b) for a, b in zip(self, other, strict=True))

    __hash__ = None  # type: ignore[assignment]  # mutable (append), like a list

    def __repr__(self) -> str:
        return f"RecordLog({len(self)} records, {len(self._recent)} in memory, {self._end} bytes on disk)"


def _same(a: object, b: object) -> bool:
    """Equality by value, field by field: arrays by content and NaN equal to NaN (a record read
    back equals the record written, which a dataclass's own ``==`` cannot say of its arrays)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return (isinstance(a, np.ndarray) and isinstance(b, np.ndarray) and a.shape == b.shape
                and a.dtype == b.dtype and bool(np.array_equal(a, b, equal_nan=a.dtype.kind in "fc")))
    if type(a) is not type(b):
        return False
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (math.isnan(a) and math.isnan(b))
    if dataclasses.is_dataclass(a):
        return all(_same(getattr(a, f.name), getattr(b, f.name)) for f in dataclasses.fields(a))
    if isinstance(a, tuple | list) and isinstance(b, tuple | list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    slots = [n for c in type(a).__mro__ for n in getattr(c, "__slots__", ())]
    if slots:
        return all(_same(getattr(a, n, None), getattr(b, n, None)) for n in slots)
    return bool(a == b)


__all__ = ["KEEP_IN_MEMORY", "RecordLog"]
