"""Ctrl-C as a request: the first SIGINT asks a long command to stop between two frames (it then
writes what it has and exits 130); a second one stops it at once (KeyboardInterrupt)."""

from __future__ import annotations

import signal
import threading
from types import FrameType, TracebackType
from typing import Any


class StopRequest:
    """``with StopRequest() as stop:`` ... ``if stop(): break``. Outside the main thread (where
    signal handlers cannot be set) Ctrl-C keeps its default behaviour."""

    def __init__(self) -> None:
        self.requested = False
        self._previous: Any = None
        self._installed = False

    def _handler(self, signum: int, frame: FrameType | None) -> None:
        self.requested = True
        signal.signal(signal.SIGINT, signal.default_int_handler)  # the next one stops at once

    def __enter__(self) -> StopRequest:
        if threading.current_thread() is threading.main_thread():
            self._previous = signal.signal(signal.SIGINT, self._handler)
            self._installed = True
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        if self._installed:
            signal.signal(signal.SIGINT, self._previous)
            self._installed = False

    def __call__(self) -> bool:
        return self.requested


__all__ = ["StopRequest"]
