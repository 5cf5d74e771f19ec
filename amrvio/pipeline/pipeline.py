"""The per-frame loop, in the order of the seed's flowchart: FrameDiagnostics -> blur gate ->
Tracker (owns the TrackSet) -> Initializer (InitResult) -> LocalMapping (keyframes, triangulation,
local BA) -> scale sources (camera height) -> VioStage (with an IMU) -> TrajectoryComposer.

``Pipeline.process(image, t_ns)`` returns the frame's :class:`FrameRecord`; ``finish()`` composes
the refined trajectory and returns every record with its final pose. The pipeline wires the
stages and owns the records (a :class:`RecordLog`); each stage owns its own state.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from amrvio.config import PipelineConfig, in_tracked_pixels
from amrvio.diagnostics.blur import BlurResult, BlurScorer, blur_score, no_signal
from amrvio.diagnostics.frame import FrameDiagnostics, FrameHealth
from amrvio.estimator.camera_height import HeightEstimate
from amrvio.estimator.initializer import Initializer, InitResult
from amrvio.estimator.local_mapping import KeyframeReport, LocalMapping
from amrvio.estimator.scale_sources import make_scale_source
from amrvio.frontend.keyframe_policy import KeyframeReason
from amrvio.frontend.tracker import Tracker
from amrvio.frontend.tracking_types import Observations, TrackingReport, TrackOutcome
from amrvio.pipeline.composer import AnchorKind, PoseAnchor, RefineGates, TrajectoryComposer, to_se3
from amrvio.pipeline.record_log import RecordLog
from amrvio.pipeline.records import EstimatorReport, FrameRecord, PipelineOutput, PoseStatus, reference_time
from amrvio.pipeline.recovery import MapRecovery, implausible_jump, link_to_previous
from amrvio.pipeline.smear_motion import ROUGH_POSES, with_translation
from amrvio.pipeline.vio_stage import ImuSetup, SensorStages, VioStage, vio_input
from amrvio.types.camera import CameraModel
from amrvio.types.lie import Sim3, se3_matrix_inverse
from amrvio.types.sensors import ImuData, WheelData

F64 = NDArray[np.float64]
U8 = NDArray[np.uint8]


@dataclass(frozen=True, slots=True)
class _Step:
    """What one frame produced, before it becomes a record: the pose anchor, the absolute
    ``T_cam_world`` (4x4, current segment) known now, and the stage reports."""

    anchor: PoseAnchor
    T_cam_world: F64
    tracking: TrackingReport
    init: InitResult | None = None
    keyframe: KeyframeReport | None = None
    scale: HeightEstimate | None = None


class Pipeline:
    """Monocular VO with per-frame diagnostics.

    ``camera``: the camera model (images are undistorted to its pinhole before tracking; the
    diagnostics see the raw image), or a pinhole ``K`` (3x3) for undistorted images.
    ``diagnostics``: the FrameDiagnostics stage (None: off; see ``pipeline.diagnose``).
    The blur gate scores every image with ``diagnostics.blur.blur_score`` (BlurScorerConfig); with
    VIO the gyro-predicted smear decides with it which frames the VIO bridges (VioStage.blur_gate),
    and the gyro's rotation since the tracker's reference image predicts its KLT flow."""

    def __init__(self, camera: CameraModel | F64, config: PipelineConfig | None = None,
                 diagnostics: FrameDiagnostics | None = None, imu: ImuSetup | None = None,
                 wheel: WheelData | None = None) -> None:
        self.cfg = config or PipelineConfig()
        self.camera = camera if isinstance(camera, CameraModel) else None
        cfg = in_tracked_pixels(self.cfg, None if self.camera is None else self.camera.width)
        K = np.asarray(camera.pinhole().K if isinstance(camera, CameraModel) else camera, dtype=np.float64)
        vio_on = imu is not None and cfg.vio.enabled and cfg.track
        self.tracker = Tracker(K, cfg.tracking, cfg.seed)
        self.initializer = Initializer(K, cfg.init, cfg.seed)
        self.mapping = LocalMapping(K, cfg.mapping)
        self.scale = make_scale_source(cfg.scale, cfg.seed, wheel)
        self.recovery = MapRecovery(K, cfg.recovery, cfg.seed, cfg.tracking.klt.max_width_px)
        tr = cfg.tracking
        self.composer = TrajectoryComposer(K, RefineGates(cfg.output.final_refine, tr.min_pnp_inliers, tr.huber_px,
                                                          tr.pnp_thresh_px))
        vio = VioStage(cfg.vio, K, imu, self.mapping) if vio_on and imu is not None else None
        self.sensors = SensorStages(diagnostics, vio)
        self.blur = BlurScorer(cfg.diagnostics.blur)
        self.records = RecordLog()
        self.timings: dict[str, float] = {}

    def _toc(self, stage: str, t0: float) -> None:
        self.timings[stage] = self.timings.get(stage, 0.0) + time.perf_counter() - t0

    # ------------------------------------------------------------------ the loop
    def process(self, image: U8, t_ns: int, imu: ImuData | None = None,
                exposure_s: float | None = None) -> FrameRecord:
        """Consume the next grey image (H, W) uint8 taken at ``t_ns``; ``imu``: the IMU samples
        since the previous frame (for the diagnostics)."""
        index = len(self.records)
        health = None
        if self.sensors.diagnostics is not None:
            t0 = time.perf_counter()
            health = self.sensors.diagnostics.process(image, t_ns, imu, exposure_s, index)
            self._toc("diagnostics", t0)
        cam = self.camera
        undistorted = False
        if cam is not None and self.cfg.track and any(abs(c) > 0 for c in cam.distortion):
            t0 = time.perf_counter()
            image = np.asarray(cam.undistort_image(image), dtype=np.uint8)
            undistorted = True
            self._toc("undistort", t0)
        t0 = time.perf_counter()  # the diagnostics scored this image already, unless undistorted since
        score = health.blur.score if health is not None and not undistorted else blur_score(image)
        events: list[str] = []
        if no_signal(image):
            # a covered lens or a black frame: nothing to track, and its sensor noise must not
            # become the blur reference (it would make the next sharp frames look blurred)
            blur = BlurResult(score, float("nan"), float("nan"), False)
            blurred = True
            events.append("no_signal")
        else:
            blur = self.blur.update(score)
            vio, gate = self.sensors.vio, self.cfg.blur_gating
            blurred = (vio.blur_gate(blur.is_blurred, health, events) if vio else blur.is_blurred) and gate
        self._toc("blur", t0)
        if not self.cfg.track:
            rec = FrameRecord(index, t_ns, PoseStatus.LOST, None, None, None, 1.0, (), blur, health,
                              None, EstimatorReport())
            self.records.append(rec)
            return rec
        if self.tracker.started and not blurred and self.tracker.is_repeat(image):
            # a recorder that repeats frames: the image shows the previous frame's view
            events.append("repeated_frame")
            T_cw = self.tracker.motion.T_last if self.tracker.mapped and \
                self.tracker.motion.T_last is not None else np.eye(4)
            anchor = PoseAnchor(PoseStatus.TRACKED, AnchorKind.FRAME, self._segment_id(), None,
                                np.eye(4), None, index - 1)
            step = _Step(anchor, T_cw, self.tracker.repeated_report())
        elif not self.tracker.started:
            step = self._start(index, image, events, keep_tracks=False)
        elif not self.tracker.mapped:
            step = self._init_step(index, image, blurred, events)
        else:
            R = None if self.sensors.vio is None else self.sensors.vio.camera_rotation(
                reference_time(self.records, self.tracker.gap), t_ns, imu)
            step = self._track_step(index, image, blurred, events, R)
        return self._emit(index, t_ns, blur, health, step, events, imu)

    def _emit(self, index: int, t_ns: int, blur: BlurResult, health: FrameHealth | None,
              step: _Step, events: list[str], imu: ImuData | None) -> FrameRecord:
        self.composer.add(step.anchor)
        diag, seg = self.sensors.diagnostics, self._segment_id()
        if diag is not None and health is not None:  # the smear's translation (pipeline.smear_motion)
            tracked = step.anchor.status is PoseStatus.TRACKED and self.tracker.mapped and \
                step.tracking.outcome not in ROUGH_POSES
            diag.observe_pose(t_ns, index if tracked else None, seg)
            m = self.mapping.current.mapper.map if self.tracker.mapped and seg is not None else None
            health = with_translation(diag, health, self.sensors.vio, t_ns, imu, m, self.tracker.tracks,
                                      lambda i: None if m is None else self.composer.pose_in_segment(i, seg, m))
        kf = (self._segment_id() or 0, step.keyframe.kf_id) if step.keyframe is not None else None
        t0 = time.perf_counter()
        vio = None if self.sensors.vio is None else self.sensors.vio.process(
            index, vio_input(t_ns, imu, step.tracking.outcome, self.tracker.tracks, kf, health), events)
        self._toc("vio", t0)
        segs = self.mapping.segments
        T_wc = segs[-1].pose_in_world(step.T_cam_world) if segs else se3_matrix_inverse(step.T_cam_world)
        tracking = dataclasses.replace(step.tracking, n_tracks=len(self.tracker.tracks))
        rec = FrameRecord(index, t_ns, step.anchor.status, to_se3(T_wc), None,
                          step.anchor.segment, 1.0, tuple(events), blur, health, tracking,
                          EstimatorReport(step.init, step.keyframe, step.scale, vio))
        self.records.append(rec)
        return rec

    def _segment_id(self) -> int | None:
        return len(self.mapping.segments) - 1 if self.mapping.segments else None

    def _absolute(self, status: PoseStatus, T_cw: F64) -> PoseAnchor:
        return PoseAnchor(status, AnchorKind.ABSOLUTE, self._segment_id(), None, T_cw.copy())

    def _on_keyframe(self, T_cw: F64, kf_id: int, obs: Observations | None) -> PoseAnchor:
        """A tracked pose, kept relative to keyframe ``kf_id`` so that BA moves it along."""
        T_kf = self.mapping.current.mapper.map.keyframes[kf_id].T_cam_world
        return PoseAnchor(PoseStatus.TRACKED, AnchorKind.KEYFRAME, self._segment_id(), kf_id,
                          T_cw @ se3_matrix_inverse(T_kf), obs, None)

    # ------------------------------------------------------------------ before a map
    def _start(self, index: int, img: U8, events: list[str], keep_tracks: bool,
               init: InitResult | None = None) -> _Step:
        """Frame ``index`` becomes the reference of a new initialisation attempt."""
        self.tracker.restart(img, keep_tracks)
        self.initializer.begin(index, img, self.tracker.tracks, keep_tracks)
        T_guess = self.tracker.motion.guess()
        return _Step(self._absolute(PoseStatus.LOST, T_guess), T_guess,
                     self.tracker.started_report(), init)

    def _init_step(self, index: int, img: U8, blurred: bool, events: list[str]) -> _Step:
        report = self.tracker.track_to_reference(img, blurred)
        ref = self.composer.anchors[self.initializer.ref_index]
        T_hold = ref.T_cam_ref if ref.kind is AnchorKind.ABSOLUTE else np.eye(4)
        if blurred:
            return _Step(self._absolute(PoseStatus.LOST, T_hold), T_hold, report)
        if self.recovery.target is not None:
            found = self._try_reloc(self.recovery.target, img, events, report)
            if found is not None:
                return found
        res = self.initializer.attempt(index, self.tracker.tracks)
        if res.ok:
            return self._make_map(index, img, res, report, events)
        if res.T_cur_ref is not None and not res.static:
            events.append("rotation_only")
        if res.restart:
            events.append(f"init_failed:{res.status.value}")
            step = self._start(index, img, events, True, res)
            if res.T_cur_ref is not None:
                # the camera rotated (or rested) since the old reference: it hangs on this frame
                old = self.composer.anchors[res.ref_index]
                self.composer.replace(res.ref_index, dataclasses.replace(
                    old, status=PoseStatus.TRACKED, kind=AnchorKind.FRAME,
                    T_cam_ref=se3_matrix_inverse(res.T_cur_ref), ref_frame=index))
            return step
        if res.T_cur_ref is not None:
            anchor = PoseAnchor(PoseStatus.TRACKED, AnchorKind.FRAME, None, None,
                                res.T_cur_ref.copy(), None, res.ref_index)
            return _Step(anchor, T_hold, report, res)
        return _Step(self._absolute(PoseStatus.LOST, T_hold), T_hold, report, res)

    def _make_map(self, index: int, img: U8, res: InitResult, report: TrackingReport,
                  events: list[str]) -> _Step:
        ref = res.ref_index
        R_g, t_g, s_g = np.eye(3), np.zeros(3), 1.0
        if self.mapping.segments:
            # link the new segment to the world through the reference frame's last known pose;
            # keep the previous segment's typical speed: |t| = 1 map unit spans (index - ref)
            # frames. A guess, logged as such; --camera-height corrects it.
            T_world_ref = self.composer.pose_in_world(ref, self.mapping.segments)
            R_g, t_g = T_world_ref[:3, :3], T_world_ref[:3, 3]
            s_g = max(self.tracker.motion.typical_speed() * (index - ref), 1e-6)
            events.append(f"segment_scale_guess:{s_g:.4g}")
        self.recovery.give_up()
        seg = self.mapping.new_segment(Sim3.from_srt(s_g, R_g, t_g))
        seg_id = len(self.mapping.segments) - 1
        tracks = self.tracker.tracks
        new = self.initializer.build(index, tracks, seg.mapper)
        if seg_id > 0:  # placed by the points it shares with the previous map, when it can
            seg, ev = link_to_previous(self.mapping.segments, seg_id, self.cfg.recovery.link,
                                       self.cfg.seed)
            events.append(ev)
        for fp in new.between:
            old = self.composer.anchors[fp.index]
            if fp.T_cam_kf0 is not None:
                anchor = PoseAnchor(PoseStatus.TRACKED, AnchorKind.KEYFRAME, seg_id, new.kf0,
                                    fp.T_cam_kf0, fp.observations, None)
            elif old.kind is AnchorKind.FRAME:
                continue  # a rotation (or rest) relative to a frame that gets a pose
            else:
                anchor = dataclasses.replace(old, status=PoseStatus.INTERPOLATED,
                                             kind=AnchorKind.INTERPOLATE, segment=seg_id,
                                             keyframe=None, ref_frame=None)
            self.composer.replace(fp.index, anchor)
        old_ref = self.composer.anchors[ref]
        self.composer.replace(ref, dataclasses.replace(
            old_ref, status=PoseStatus.TRACKED, kind=AnchorKind.KEYFRAME, segment=seg_id,
            keyframe=new.kf0, T_cam_ref=np.eye(4)))
        self.tracker.adopt_map_pose(new.T_cam_world, new.velocity)
        self.tracker.detect(img, new.kf1)
        reading = self.scale.observe_keyframe(seg, new.kf1)
        if self.initializer.ref_img is not None:
            self.mapping.keep_image(new.kf0, self.initializer.ref_img)
            self.recovery.add_keyframe(seg_id, new.kf0, self.initializer.ref_img, seg.mapper.map)
        self.mapping.seal_keyframe(new.kf1, img, tracks)
        self.recovery.add_keyframe(seg_id, new.kf1, img, seg.mapper.map)
        events.append(f"init_ok:ref={ref}")
        kf = KeyframeReport(new.kf1, None, 0, None, None)
        report = dataclasses.replace(report, n_inliers=res.n_points)
        return _Step(self._on_keyframe(new.T_cam_world, new.kf1, None), new.T_cam_world, report,
                     res, kf, reading)

    # ------------------------------------------------------------------ with a map
    def _track_step(self, index: int, img: U8, blurred: bool, events: list[str], R_cur_ref: F64 | None) -> _Step:
        seg = self.mapping.current
        tracks = self.tracker.tracks
        stale = not blurred and self.tracker.stale(self.cfg.recovery.max_bridge_frames) and R_cur_ref is None
        if stale:  # back after a long gap (blur, a covered lens): the motion model is stale, the map is
            # searched first; with the gyro's rotation the tracks go first (they keep the smoother's landmarks)
            reloc = self._try_reloc(len(self.mapping.segments) - 1, img, events)
            self.recovery.give_up()
            if reloc is not None:
                return reloc
        bridged = self.sensors.vio is not None and self.sensors.vio.running  # blurred frames are the IMU's
        step = self.tracker.track(img, blurred, seg.mapper.map, seg.world_from_segment.s, R_cur_ref, stale, bridged)
        rep = step.report
        if rep.direct_prior:
            events.append("direct_prior")
        if rep.outcome in (TrackOutcome.DIRECT, TrackOutcome.ROTATION, TrackOutcome.SCALED_RELATIVE):
            events.append(rep.outcome.value)  # a fallback pose (SCALED_RELATIVE: see n_inliers)
        last_kf = len(seg.mapper.map.keyframes) - 1
        if rep.outcome is TrackOutcome.PREDICTED:
            return _Step(self._absolute(PoseStatus.INTERPOLATED, step.T_cam_world),
                         step.T_cam_world, rep)
        if rep.outcome is TrackOutcome.LOST:
            events.append(f"lost:{rep.pnp_status}")
            found = self._try_reloc(len(self.mapping.segments) - 1, img, events, rep)
            if found is not None:
                return found
            # the surviving tracks stay: they link the next map to this one
            lost = self._start(index, img, events, keep_tracks=True)
            return dataclasses.replace(lost, tracking=dataclasses.replace(lost.tracking,
                                                                          outcome=TrackOutcome.LOST))
        if rep.outcome is TrackOutcome.DIRECT:
            return _Step(self._on_keyframe(step.T_cam_world, last_kf, None), step.T_cam_world, rep)
        if rep.outcome in (TrackOutcome.TRACKED_BLURRED, TrackOutcome.BLURRED_REFERENCE):
            return _Step(self._on_keyframe(step.T_cam_world, last_kf, step.observations),
                         step.T_cam_world, rep)
        reason = self.mapping.keyframe_due(index, rep.n_inliers, tracks)
        if reason is KeyframeReason.NONE:
            return _Step(self._on_keyframe(step.T_cam_world, last_kf, step.observations),
                         step.T_cam_world, rep)
        return self._keyframe(index, img, step.T_cam_world, reason, rep)

    def _keyframe(self, index: int, img: U8, T_cam_world: F64, reason: KeyframeReason,
                  rep: TrackingReport) -> _Step:
        seg = self.mapping.current
        tracks = self.tracker.tracks
        T_cw, kf = self.mapping.add_keyframe(index, T_cam_world, img, tracks, reason)
        self.tracker.motion.T_last = T_cw
        self.tracker.detect(img, kf.kf_id)
        self.mapping.seal_keyframe(kf.kf_id, img, tracks)
        self.recovery.add_keyframe(len(self.mapping.segments) - 1, kf.kf_id, img, seg.mapper.map)
        self.composer.settle(self.mapping.segments, 2 * self.mapping.ba_span)  # pose fixed twice the BA window behind
        reading = self.scale.observe_keyframe(seg, kf.kf_id)
        return _Step(self._on_keyframe(T_cw, kf.kf_id, None), T_cw, rep, None, kf, reading)

    def _try_reloc(self, segment: int, img: U8, events: list[str],
                   rep: TrackingReport | None = None) -> _Step | None:
        """Search ``segment``'s map for ``img``; the relocalised step, or None."""
        self.recovery.lost(segment)
        reloc = self.recovery.attempt(img, self.mapping.segments[segment].mapper.map,
                                      len(self.records))
        if reloc is None:
            return None
        if not reloc.ok or reloc.T_cam_world is None:
            events.append(f"reloc_failed:{reloc.status.value}:{reloc.n_matches}:{reloc.n_inliers}")
            return None
        since = next((k for k, r in enumerate(reversed(self.records))
                      if r.status is PoseStatus.TRACKED), len(self.records)) + 1
        far = implausible_jump(reloc.T_cam_world, self.tracker.motion.T_last,
                               self.mapping.segments[segment].world_from_segment.s,
                               self.tracker.motion.typical_speed(), since)
        if far is not None:
            # a repeated structure (shelves, posters) can look like the place: a pose farther
            # from the last known one than the robot could have gone is refused
            events.append(f"reloc_rejected:jump={far:.3g}")
            self.recovery.lost(segment)
            return None
        if rep is None:
            rep = self.tracker.started_report()
        return self._relocalised(len(self.records), img, reloc.T_cam_world, reloc.point_ids,
                                 reloc.uv, rep, events)

    def _relocalised(self, index: int, img: U8, T_cam_world: F64, ids: NDArray[np.int64],
                     uv: F64, rep: TrackingReport, events: list[str]) -> _Step:
        """Found again in the lost map: the tracks restart on the map points that matched, and
        the frame becomes a keyframe of the same segment (one map, one scale)."""
        self.tracker.tracks.reset(ids, uv)
        self.tracker.resume(img, T_cam_world)
        events.append(f"relocalised:{len(ids)}")
        rep = dataclasses.replace(rep, outcome=TrackOutcome.TRACKED, n_inliers=len(ids))
        return self._keyframe(index, img, T_cam_world, KeyframeReason.RELOCALISED, rep)

    # ------------------------------------------------------------------ the end
    def all_timings(self) -> dict[str, float]:
        out = dict(self.timings)
        for part in (self.tracker.timings, self.initializer.timings, self.mapping.all_timings(),
                     self.scale.timings, self.recovery.timings):
            for k, v in part.items():
                out[k] = out.get(k, 0.0) + v
        return out

    def finish(self) -> PipelineOutput:
        """Compose the refined trajectory; every record gets its final status and pose."""
        n = len(self.records)
        stamps = np.fromiter((r.t_ns for r in self.records), dtype=np.int64, count=n)
        if not self.cfg.track:
            return PipelineOutput(self.records, stamps, np.zeros((0, 4, 4)), np.zeros(0, dtype=np.int64),
                                  np.zeros((0, 3)), (), np.ones(n), self.all_timings())
        fs = self.scale.frame_scales(n, stamps) if self.scale.active else np.ones(n)
        unscaled = self.composer.finish(self.mapping.segments)  # the VIO puts these in its world, at its scale
        composed = unscaled.scaled(fs) if self.scale.active else unscaled
        g_scale = float(np.median(fs)) if n else 1.0
        pts = [sg.points_in_world(g_scale) for sg in self.mapping.segments]
        vio, statuses = self.sensors.vio, list(composed.statuses)
        body, statuses = vio.finish(unscaled.T_world_cam, statuses, self.mapping.segments) if vio else (None, statuses)
        kf_idx = np.array([i for i, r in enumerate(self.records) if r.is_keyframe], dtype=np.int64)
        done, self.records = self.records, RecordLog(dataclasses.replace(
            r, status=statuses[i], pose_refined=to_se3(composed.T_world_cam[i]),
            segment=self.composer.anchors[i].segment, scale_factor=float(fs[i])) for i, r in enumerate(self.records))
        done.close()
        return PipelineOutput(self.records, stamps, composed.T_world_cam, kf_idx,
                              np.vstack(pts) if pts else np.zeros((0, 3)),
                              tuple(self.scale.readings), fs, self.all_timings(), body)


__all__ = ["Pipeline", "PipelineOutput"]
