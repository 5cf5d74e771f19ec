"""TrajectoryComposer: the final pose of every frame, from what each frame was anchored to.

While the run goes, each frame gets a :class:`PoseAnchor`: its pose relative to a keyframe of a
map segment, an absolute pose (before a map, or a guess), or nothing (to interpolate). At the end
the composer reads the bundle-adjusted keyframes, refines non-keyframe poses against the final
map, resolves frames that share the pose of another (a camera at rest before initialisation),
interpolates the rest, and applies the per-frame metric scale.

A frame whose keyframe is far behind its map's newest is settled during the run
(:meth:`TrajectoryComposer.settle`): that keyframe no longer moves, so the frame is refined then
and keeps one pose instead of its observations. The memory of a long run stays bounded.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from enum import Enum
from typing import overload

import numpy as np
from numpy.typing import NDArray

from amrvio.estimator.local_mapping import Segment
from amrvio.estimator.vo_map import VoMap
from amrvio.frontend.tracking_types import Observations
from amrvio.geometry.pnp import refine_pose_huber
from amrvio.geometry.projection import project
from amrvio.pipeline.records import PoseStatus
from amrvio.types.lie import SE3, SO3, se3_matrix_inverse

F64 = NDArray[np.float64]


class AnchorKind(Enum):
    """What ``PoseAnchor.T_cam_ref`` is relative to."""

    KEYFRAME = "keyframe"  # keyframe ``keyframe`` of ``segment``
    ABSOLUTE = "absolute"  # the world of ``segment`` (the global world when segment is None)
    FRAME = "frame"  # frame ``ref_frame``, whatever its pose turns out to be
    INTERPOLATE = "interpolate"  # no pose of its own: interpolated between tracked neighbours


@dataclass(frozen=True, slots=True)
class PoseAnchor:
    """How a frame's pose is composed at the end. ``ref_frame`` (kind FRAME): the frame's pose
    is ``T_cam_ref`` relative to that frame's (before initialisation: a camera at rest, identity,
    or one that only rotated, a rotation); it is tracked when that one is."""

    status: PoseStatus
    kind: AnchorKind
    segment: int | None
    keyframe: int | None
    T_cam_ref: F64
    observations: Observations | None = None
    ref_frame: int | None = None


@dataclass(frozen=True, slots=True)
class RefineGates:
    """Motion-only refinement of non-keyframe poses against the final map: on/off, the PnP
    inlier count it needs, the Huber threshold and the median reprojection it must reach (px)."""

    enabled: bool
    min_points: int
    huber_px: float
    max_median_px: float


@dataclass(frozen=True, slots=True)
class ComposedTrajectory:
    """(N, 4, 4) ``T_world_cam`` and the (N,) final statuses."""

    T_world_cam: F64
    statuses: tuple[PoseStatus, ...]

    def scaled(self, frame_scale: F64) -> ComposedTrajectory:
        """The metric trajectory: each position increment scaled by the (N,) per-frame scale
        (the mean of its two frames'; smoothed per keyframe by the scale source)."""
        T_wc = self.T_world_cam.copy()
        p = T_wc[:, :3, 3].copy()
        q = p.copy()
        if len(p):
            q[0] = p[0] * frame_scale[0]
        for i in range(1, len(p)):
            q[i] = q[i - 1] + 0.5 * (frame_scale[i] + frame_scale[i - 1]) * (p[i] - p[i - 1])
        T_wc[:, :3, 3] = q
        return ComposedTrajectory(T_wc, self.statuses)


def to_se3(T: F64) -> SE3:
    """A 4x4 pose as an SE3 value, bit-exact (no re-orthonormalisation)."""
    return SE3(SO3(T[:3, :3]), T[:3, 3])


_STATUSES = tuple(PoseStatus)
_KINDS = tuple(AnchorKind)


class AnchorBook(Sequence[PoseAnchor]):
    """The frames' anchors in columns: one 4x4 pose and five small integers a frame (status,
    kind, segment, keyframe, reference frame; -1 for None), and the observations of the frames
    not settled yet. A long run keeps 168 bytes a frame instead of two Python objects and a
    separate 4x4 array (about 350 bytes). ``book[i]`` is the :class:`PoseAnchor` of frame ``i``,
    a value (its pose is a copy), ``book[i:j]`` a list of them; ``book[i] = anchor`` replaces one."""

    def __init__(self) -> None:
        self._n = 0
        self._T = np.zeros((0, 4, 4))
        self._meta = np.zeros((0, 5), dtype=np.int64)
        self._obs: dict[int, Observations] = {}

    def __len__(self) -> int:
        return self._n

    def append(self, anchor: PoseAnchor) -> None:
        row = _meta_row(anchor)  # checked before anything is written
        if self._n == len(self._T):
            cap = max(self._n + self._n // 2, 256)
            T, meta = np.zeros((cap, 4, 4)), np.zeros((cap, 5), dtype=np.int64)
            T[: self._n], meta[: self._n] = self._T[: self._n], self._meta[: self._n]
            self._T, self._meta = T, meta
        self._n += 1
        self._write(self._n - 1, anchor, row)

    @overload
    def __getitem__(self, index: int) -> PoseAnchor: ...

    @overload
    def __getitem__(self, index: slice) -> list[PoseAnchor]: ...

    def __getitem__(self, index: int | slice) -> PoseAnchor | list[PoseAnchor]:
        if isinstance(index, slice):
            return [self[i] for i in range(*index.indices(self._n))]
        i = self._at(index)
        st, kind, seg, kf, ref = (int(v) for v in self._meta[i])
        return PoseAnchor(_STATUSES[st], _KINDS[kind], None if seg < 0 else seg, None if kf < 0 else kf,
                          self._T[i].copy(), self._obs.get(i), None if ref < 0 else ref)

    def __setitem__(self, index: int, a: PoseAnchor) -> None:
        self._write(self._at(index), a, _meta_row(a))

    def _write(self, i: int, a: PoseAnchor, row: tuple[int, ...]) -> None:
        self._T[i] = a.T_cam_ref
        self._meta[i] = row
        if a.observations is None:
            self._obs.pop(i, None)
        else:
            self._obs[i] = a.observations

    def _at(self, index: int) -> int:
        if not -self._n <= index < self._n:
            raise IndexError(f"anchor {index} of {self._n}")
        return index % self._n


def _meta_row(a: PoseAnchor) -> tuple[int, ...]:
    """(status, kind, segment, keyframe, reference frame) as integers, -1 for None."""
    ids = (a.segment, a.keyframe, a.ref_frame)
    if any(v is not None and v < 0 for v in ids):
        raise ValueError(f"an anchor's segment, keyframe and frame index are never negative, got {ids}")
    return (_STATUSES.index(a.status), _KINDS.index(a.kind), *(-1 if v is None else int(v) for v in ids))


class TrajectoryComposer:
    """Construct with the pinhole ``K`` (3x3) and the refinement gates."""

    def __init__(self, K: F64, gates: RefineGates) -> None:
        self.K = K
        self.gates = gates
        self.anchors = AnchorBook()
        self._settled = 0  # anchors before this one were looked at by :meth:`settle`

    def add(self, anchor: PoseAnchor) -> None:
        self.anchors.append(anchor)

    def replace(self, index: int, anchor: PoseAnchor) -> None:
        """Re-anchor frame ``index`` (a new map's initialisation poses the frames of its history);
        :meth:`settle` looks at it again."""
        self.anchors[index] = anchor
        self._settled = min(self._settled, index)

    def settle(self, segments: list[Segment], keep_keyframes: int) -> None:
        """Refine now, against the map as it is, the frames tracked relative to a keyframe at
        least ``keep_keyframes`` behind the newest of the current map (or of an earlier map):
        each becomes absolute in its segment and drops its observations. With ``keep_keyframes``
        beyond the local BA window the keyframe's pose is final; the points it sees may still move
        a little while newer keyframes see them."""
        while self._settled < len(self.anchors):
            a = self.anchors[self._settled]
            if a.kind is AnchorKind.KEYFRAME and a.observations is not None and a.segment is not None \
                    and a.keyframe is not None:
                m = segments[a.segment].mapper.map
                if a.segment == len(segments) - 1 and a.keyframe > len(m.keyframes) - 1 - keep_keyframes:
                    return
                self.anchors[self._settled] = dataclasses.replace(
                    a, kind=AnchorKind.ABSOLUTE, keyframe=None, T_cam_ref=self._keyframe_pose(a, m),
                    observations=None)
            self._settled += 1

    def pose_in_world(self, index: int, segments: list[Segment]) -> F64:
        """4x4 ``T_world_cam`` of an anchored frame with the keyframes as they are now."""
        a = self.anchors[index]
        sg = segments[a.segment] if a.segment is not None else None
        T_cw = a.T_cam_ref
        if a.kind is AnchorKind.FRAME and a.ref_frame is not None:
            return self.pose_in_world(a.ref_frame, segments) @ se3_matrix_inverse(a.T_cam_ref)
        if a.kind is AnchorKind.KEYFRAME and sg is not None and a.keyframe is not None:
            T_cw = a.T_cam_ref @ sg.mapper.map.keyframes[a.keyframe].T_cam_world
        return sg.pose_in_world(T_cw) if sg is not None else se3_matrix_inverse(T_cw)

    def pose_in_segment(self, index: int, segment: int | None, m: VoMap) -> F64 | None:
        """4x4 ``T_cam_world`` of frame ``index`` in ``segment`` (whose map is ``m``) with the
        keyframes as they are now; None for a frame of another segment, or whose pose is
        neither relative to a keyframe nor absolute in the segment."""
        a = self.anchors[index]
        if segment is None or a.segment != segment:
            return None
        if a.kind is AnchorKind.KEYFRAME and a.keyframe is not None:
            return a.T_cam_ref @ m.keyframes[a.keyframe].T_cam_world
        return a.T_cam_ref if a.kind is AnchorKind.ABSOLUTE else None

    def _keyframe_pose(self, a: PoseAnchor, m: VoMap) -> F64:
        """4x4 ``T_cam_world`` of a frame anchored to keyframe ``a.keyframe`` of map ``m``, refined
        against the map's points when it has observations (the same at the end and when settled)."""
        assert a.keyframe is not None
        T_cw = a.T_cam_ref @ m.keyframes[a.keyframe].T_cam_world
        if self.gates.enabled and a.observations is not None:
            T_cw = self._refine(m, T_cw, a.observations)
        return T_cw

    def _refine(self, m: VoMap, T_cw: F64, obs: Observations) -> F64:
        has = m.points_of(obs.ids)
        if int(has.sum()) < self.gates.min_points:
            return T_cw
        X = m.xyz[obs.ids[has]]
        T = refine_pose_huber(T_cw, X, obs.uv[has], self.K, huber_px=self.gates.huber_px,
                              iterations=5)
        proj, _ = project(self.K, T, X)
        err = np.linalg.norm(proj - obs.uv[has], axis=1)
        if not np.all(np.isfinite(T)) or float(np.median(err)) > self.gates.max_median_px:
            return T_cw
        return T

    def finish(self, segments: list[Segment]) -> ComposedTrajectory:
        """Compose all poses, in the segments' units (:meth:`ComposedTrajectory.scaled` applies a
        scale source's per-frame scale)."""
        n = len(self.anchors)
        T_wc = np.zeros((n, 4, 4))
        for i, a in enumerate(self.anchors):
            if a.kind in (AnchorKind.INTERPOLATE, AnchorKind.FRAME):
                continue
            sg = segments[a.segment] if a.segment is not None else None
            if a.kind is AnchorKind.KEYFRAME and sg is not None and a.keyframe is not None:
                T_cw = self._keyframe_pose(a, sg.mapper.map)
            else:
                T_cw = a.T_cam_ref
            T_wc[i] = sg.pose_in_world(T_cw) if sg is not None else se3_matrix_inverse(T_cw)
        statuses = self._resolve_frames(T_wc)
        tracked = np.flatnonzero([s is PoseStatus.TRACKED for s in statuses])
        if len(tracked):
            T_wc = _fill_interpolated(T_wc, statuses, tracked)
        return ComposedTrajectory(T_wc, tuple(statuses))


    def _resolve_frames(self, T_wc: F64) -> list[PoseStatus]:
        """Frames anchored to another frame (at rest or rotating before an initialisation) take
        its final pose composed with theirs, and are tracked when it is; ``T_wc`` is filled in."""
        statuses = [a.status for a in self.anchors]
        n = len(self.anchors)
        done = [a.kind is not AnchorKind.FRAME for a in self.anchors]
        for i in range(n):
            chain = [i]
            while not done[chain[-1]] and len(chain) <= n:
                nxt = self.anchors[chain[-1]].ref_frame
                if nxt is None:
                    break
                chain.append(nxt)
            root = chain[-1]
            for k in reversed(chain[:-1]):
                a = self.anchors[k]
                if done[root] and statuses[root] is PoseStatus.TRACKED:
                    T_wc[k] = T_wc[root] @ se3_matrix_inverse(a.T_cam_ref)
                    statuses[k] = PoseStatus.TRACKED
                else:
                    statuses[k] = a.status if a.status is not PoseStatus.TRACKED else \
                        PoseStatus.LOST
                    T_wc[k] = np.eye(4)
                done[k] = True
                root = k
        return statuses


def _fill_interpolated(T_wc: F64, statuses: list[PoseStatus], tracked: NDArray[np.intp]) -> F64:
    """Interpolate non-tracked frames between tracked neighbours (SLERP + linear); hold the
    nearest tracked pose at the ends (those frames become LOST)."""
    from scipy.spatial.transform import Rotation, Slerp

    out = T_wc.copy()
    n = len(statuses)
    rots = Rotation.from_matrix(T_wc[tracked, :3, :3])
    slerp = Slerp(tracked.astype(float), rots) if len(tracked) >= 2 else None
    for i in range(n):
        if statuses[i] is PoseStatus.TRACKED:
            continue
        j = int(np.searchsorted(tracked, i))
        if 0 < j < len(tracked) and slerp is not None:
            i0, i1 = tracked[j - 1], tracked[j]
            al = (i - i0) / (i1 - i0)
            out[i] = np.eye(4)
            out[i, :3, :3] = slerp([float(i)]).as_matrix()[0]
            out[i, :3, 3] = (1 - al) * T_wc[i0, :3, 3] + al * T_wc[i1, :3, 3]
            statuses[i] = PoseStatus.INTERPOLATED
        elif statuses[i] is PoseStatus.INTERPOLATED or not np.all(np.isfinite(out[i])) or \
                abs(np.linalg.det(out[i, :3, :3]) - 1) > 1e-3:
            out[i] = T_wc[tracked[min(j, len(tracked) - 1)]]
            statuses[i] = PoseStatus.LOST
    return out


__all__ = ["AnchorBook", "AnchorKind", "ComposedTrajectory", "PoseAnchor", "RefineGates", "TrajectoryComposer",
           "to_se3"]
