"""``events.jsonl``: what happened in a run, one JSON object a line, from the frame records.

Each frame's ``events`` strings (``init_ok:ref=K``, ``init_failed:STATUS``, ``lost:STATUS``,
``relocalised:N``, ``rotation_only``, ``scaled_relative``, ``segment_scale_guess:S``,
``direct_fallback``, ``direct_prior``, and any a later stage adds) become one line each, with the
report that goes with them: the initialisation attempt
(:class:`~amrvio.estimator.initializer.InitResult`), the tracking report of a loss or of a
scaled relative pose, the keyframe made. A frame with an initialisation attempt and no init event
gets an ``init_attempt`` line; every keyframe a ``keyframe`` line (its triangulation and BA
reports); every camera-height reading a ``scale_reading`` line; every visual-inertial
initialisation a ``vi_init`` line (status, advice, excitation, figures, state) or a
``static_init`` line, and the VIO stage's ``vio_reinit`` / ``vio_failed`` events say why. After
the run, ``dropped`` lines name the ranges of frames that have no pose (final status LOST) with their likely causes, and
``skipped`` lines the images that could not be used.

Every line has ``type``, ``frame`` (the record's index, or the dataset's for a skipped image) and
``t_s``. The file holds no NaN or inf (those become null).
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Iterable, Sequence
from enum import Enum
from typing import Any

import numpy as np

from amrvio.io.base import SkippedFrame
from amrvio.pipeline.records import FrameRecord, PoseStatus

MAX_ARRAY_SIZE = 16
"""Arrays of a report up to this size (a 4x4 pose) are written out; larger ones by shape only."""

FLAG_GAP = 2
"""Flagged frames separated by at most this many unflagged ones form one range (as advice.txt)."""

CAUSES: tuple[str, ...] = ("blur", "exposure", "saturation", "low_parallax", "low_excitation",
                           "lost")
"""The causes of a flagged range, in the order tables and plots list them."""


def jsonable(value: Any) -> Any:
    """A report as JSON values: dataclasses as objects (field by field), enums by value, small
    arrays as lists, larger ones by shape, non-finite floats as None."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: jsonable(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, Enum):
        return value.value
    if isinstance(value, np.ndarray):
        if value.size > MAX_ARRAY_SIZE:
            return {"shape": list(value.shape)}
        return jsonable(value.tolist())
    if isinstance(value, np.generic):
        return jsonable(value.item())
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(v) for v in value]
    return value


def init_report(rec: FrameRecord) -> dict[str, Any] | None:
    """The initialisation attempt of a record as JSON values; its rotation to the reference
    (``T_cur_ref``) as an angle, ``rotation_to_ref_deg`` (None when there is none)."""
    init = rec.estimator.init
    if init is None:
        return None
    out: dict[str, Any] = jsonable(init)
    T = out.pop("T_cur_ref", None)
    angle = None
    if init.T_cur_ref is not None and np.all(np.isfinite(init.T_cur_ref)):
        c = (float(np.trace(init.T_cur_ref[:3, :3])) - 1.0) / 2.0
        angle = math.degrees(math.acos(min(1.0, max(-1.0, c))))
    out["rotation_to_ref_deg"] = angle if T is not None else None
    return out


def _head(rec: FrameRecord, kind: str) -> dict[str, Any]:
    return {"type": kind, "frame": rec.index, "t_s": round(rec.t_ns * 1e-9, 9)}


def _number(text: str) -> float | int | str:
    """``text`` as an int or a finite float when it is one, else the text."""
    try:
        return int(text)
    except ValueError:
        pass
    try:
        v = float(text)
    except ValueError:
        return text
    return v if math.isfinite(v) else text


def _from_string(rec: FrameRecord, event: str) -> dict[str, Any]:
    """One event string of a record, with the report that belongs to it."""
    name, _, value = event.partition(":")
    out = _head(rec, name)
    if name == "init_ok":
        _, _, ref = value.partition("=")
        out["ref_frame"] = _number(ref)
        out["segment"] = rec.segment
        out["init"] = init_report(rec)
    elif name == "init_failed":
        out["status"] = value
        out["init"] = init_report(rec)
    elif name in ("lost", "scaled_relative"):
        # scaled_relative: PnP failed (pnp_status) and the tracks' essential matrix posed the
        # frame; the tracking report's n_inliers counts the map points that fixed the length
        out["pnp_status"] = value or (rec.tracking.pnp_status if rec.tracking is not None else None)
        out["tracking"] = jsonable(rec.tracking)
    elif name == "relocalised":
        out["n_matches"] = _number(value)
        out["segment"] = rec.segment
    elif name == "segment_scale_guess":
        out["scale_guess"] = _number(value)
    elif value:
        out["value"] = _number(value)
    return out


def frame_events(rec: FrameRecord) -> list[dict[str, Any]]:
    """The ``events.jsonl`` lines of one frame record (known when it is processed)."""
    out = [_from_string(rec, e) for e in rec.events]
    est = rec.estimator
    names = {e.partition(":")[0] for e in rec.events}
    if est.init is not None and not names & {"init_ok", "init_failed"}:
        line = _head(rec, "init_attempt")
        line["init"] = init_report(rec)
        out.append(line)
    if est.keyframe is not None:
        line = _head(rec, "keyframe")
        line.update(jsonable(est.keyframe))
        out.append(line)
    if est.scale is not None:
        line = _head(rec, "scale_reading")
        line.update(jsonable(est.scale))
        out.append(line)
    vio = est.vio
    if vio is not None and vio.vi_init is not None:
        line = _head(rec, "vi_init")
        line.update(jsonable(vio.vi_init))
        out.append(line)
    if vio is not None and vio.static is not None:
        line = _head(rec, "static_init")
        line.update(jsonable(vio.static))
        out.append(line)
    return out


def flag_ranges(flags: Sequence[bool], max_gap: int = FLAG_GAP) -> list[tuple[int, int]]:
    """Position ranges ``[i0, i1]`` of the True runs; runs separated by at most ``max_gap``
    False entries merge."""
    out: list[tuple[int, int]] = []
    for i, f in enumerate(flags):
        if not f:
            continue
        if out and i - out[-1][1] <= max_gap + 1:
            out[-1] = (out[-1][0], i)
        else:
            out.append((i, i))
    return out


def frame_flags(rec: FrameRecord) -> dict[str, bool]:
    """Which causes flag one frame: the health record's flags (blur, exposure step, saturation
    over 10 %, low parallax, degenerate excitation) and a final status LOST."""
    h = rec.diagnostics
    ex = h.excitation if h is not None else None
    return {
        "blur": bool(h.blur.flag) if h is not None else bool(rec.blur.is_blurred),
        "exposure": bool(h.exposure.flag) if h is not None else False,
        "saturation": bool(h.exposure.saturated_frac > 0.1) if h is not None else False,
        "low_parallax": bool(h.parallax.low_flag) if h is not None else False,
        "low_excitation": bool(ex.degenerate) if ex is not None else False,
        "lost": rec.status is PoseStatus.LOST,
    }


def flagged_ranges(records: Sequence[FrameRecord]) -> dict[str, list[tuple[int, int]]]:
    """For each cause of :data:`CAUSES`, the ranges of record positions it flags (merged as in
    advice.txt; "lost" ranges are exact: a pose is there or not)."""
    flags = [frame_flags(r) for r in records]
    return {c: flag_ranges([f[c] for f in flags], 0 if c == "lost" else FLAG_GAP) for c in CAUSES}


def dropped_events(records: Sequence[FrameRecord]) -> list[dict[str, Any]]:
    """One ``dropped`` line per range of frames without a pose, with the causes that flag any of
    its frames, the events inside it, and whether it comes before the first map."""
    first_map = next((i for i, r in enumerate(records)
                      if any(e.startswith("init_ok") for e in r.events)), None)
    out: list[dict[str, Any]] = []
    for i0, i1 in flag_ranges([r.status is PoseStatus.LOST for r in records], 0):
        seg = records[i0:i1 + 1]
        flags = [frame_flags(r) for r in seg]
        causes = [c for c in CAUSES if c != "lost" and any(f[c] for f in flags)]
        if first_map is None or i0 < first_map:
            causes.insert(0, "before_first_map")
        line = _head(seg[0], "dropped")
        line.update({"first_frame": seg[0].index, "last_frame": seg[-1].index,
                     "n_frames": len(seg), "t_end_s": round(seg[-1].t_ns * 1e-9, 9),
                     "causes": causes,
                     "events": sorted({e.partition(":")[0] for r in seg for e in r.events})})
        out.append(line)
    return out


def skipped_event(s: SkippedFrame) -> dict[str, Any]:
    return {"type": "skipped", "frame": s.index, "t_s": round(s.t_ns * 1e-9, 9), "file": s.file,
            "problem": s.problem}


def run_events(records: Sequence[FrameRecord],
               skipped: Iterable[SkippedFrame] = ()) -> list[dict[str, Any]]:
    """Every line of a finished (or interrupted) run, by time: the frames' events, the dropped
    ranges (at their first frame) and the skipped images."""
    lines: list[tuple[float, int, dict[str, Any]]] = []
    for r in records:
        lines += [(r.t_ns * 1e-9, 1, e) for e in frame_events(r)]
    lines += [(float(d["t_s"]), 0, d) for d in dropped_events(records)]
    lines += [(s.t_ns * 1e-9, 0, skipped_event(s)) for s in skipped]
    lines.sort(key=lambda x: (x[0], x[1]))
    return [d for _, _, d in lines]


def event_line(event: dict[str, Any]) -> str:
    """One line of events.jsonl (strict JSON, keys in the order given)."""
    return json.dumps(jsonable(event), allow_nan=False, separators=(",", ":"))


__all__ = ["CAUSES", "FLAG_GAP", "MAX_ARRAY_SIZE", "dropped_events", "event_line",
           "flag_ranges", "flagged_ranges", "frame_events", "frame_flags", "init_report",
           "jsonable", "run_events", "skipped_event"]
