"""The progress bar of a run: frames done, frames per second, and a live health line.

:class:`ProgressSink` is a :class:`~amrvio.pipeline.run.FrameSink` that passes every record and
skip on to another sink and updates a tqdm bar on stderr, e.g.::

    amrvio:  42%|████▏     | 250/600 [00:31<00:44, 7.9frame/s, tracked | tracks 182 inliers 121 |
    kf 24 losses 0 | blur 12 ev 3 low-par 40 | frame 231: init_ok:ref=220]

The line after the bar: the frame's status ("initialising" before the first map), its tracks and
PnP inliers, the keyframes and losses of tracking so far, the frames flagged so far by blur,
exposure steps and low parallax, and the last event.
"""

from __future__ import annotations

import sys
from typing import Any

from amrvio.io.base import SkippedFrame
from amrvio.pipeline.events import frame_flags
from amrvio.pipeline.records import FrameRecord, PoseStatus
from amrvio.pipeline.run import FrameSink


class ProgressSink:
    """``total``: frames planned; ``inner``: the sink that writes the outputs (or None)."""

    def __init__(self, total: int, inner: FrameSink | None = None, desc: str = "amrvio") -> None:
        from tqdm import tqdm

        self.inner = inner
        self.bar: Any = tqdm(total=total, desc=desc, unit="frame", file=sys.stderr,
                             dynamic_ncols=True, mininterval=0.5)
        self.counts = {"kf": 0, "lost": 0, "blur": 0, "exposure": 0, "low_parallax": 0,
                       "skipped": 0}
        self.last_event = ""

    def record(self, rec: FrameRecord) -> None:
        if self.inner is not None:
            self.inner.record(rec)
        c = self.counts
        c["kf"] += int(rec.is_keyframe)
        c["lost"] += sum(e.startswith("lost:") for e in rec.events)
        flags = frame_flags(rec)
        for k in ("blur", "exposure", "low_parallax"):
            c[k] += int(flags[k])
        notable = [e for e in rec.events if not e.startswith(("direct_prior", "rotation_only"))]
        if notable:
            self.last_event = f"frame {rec.index}: {notable[-1]}"
        self.bar.set_postfix_str(self.health_line(rec), refresh=False)
        self.bar.update(1)

    def health_line(self, rec: FrameRecord) -> str:
        c = self.counts
        tr = rec.tracking
        mapped = rec.segment is not None or rec.status is not PoseStatus.LOST
        parts = [rec.status.value if mapped else "initialising"]
        if tr is not None:
            parts.append(f"tracks {tr.n_tracks} inliers {tr.n_inliers}")
        parts.append(f"kf {c['kf']} losses {c['lost']}")
        parts.append(f"blur {c['blur']} ev {c['exposure']} low-par {c['low_parallax']}")
        if c["skipped"]:
            parts.append(f"skipped {c['skipped']}")
        if self.last_event:
            parts.append(self.last_event)
        return " | ".join(parts)

    def skip(self, skipped: SkippedFrame) -> None:
        if self.inner is not None:
            self.inner.skip(skipped)
        self.counts["skipped"] += 1
        self.bar.update(1)

    def close(self) -> None:
        self.bar.close()


__all__ = ["ProgressSink"]
