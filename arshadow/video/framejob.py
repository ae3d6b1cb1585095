"""The frame job: one decoded frame tracked, decided (smoothing, marker loss), composited and reported.

The main thread (the GL context's) runs, per frame, :func:`gray_of` -> :meth:`SessionBackend.track` ->
:class:`arshadow.video.temporal.PoseStream` -> :meth:`FrameComposer.compose`, which renders into the
frame and returns what the encode thread writes: the frame (planar ``yuv420p`` or BGR), the mask, the
report item and the frame's JSON Lines record.

Colour: frames stay in the decoder's ``yuv420p`` when it gives that (the tracker reads the Y plane as its
grey image; OpenCV converts to BGR for the compositor, and back for the encoder, only inside the frame's
ROI, the only pixels the compositor reads and changes: every other pixel keeps its decoded value exactly;
the ROI is written back into the decoded frame's own array, so no whole frame is copied).

Rendering goes through :class:`SessionBackend`, the only place that knows the rendering API (the public
methods of :class:`arshadow.frame.session.Session`).

The ``yuv420p`` conversions inside a rectangle are :mod:`arshadow.video.i420` (re-exported here).
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Sequence
from datetime import datetime, timedelta
from os import PathLike
from typing import TYPE_CHECKING, Any, TypeAlias, TypedDict, cast

import cv2
import numpy as np

from ..errors import MarkerNotFoundError
from ..frame.effects import touched_roi
from ..frame.execute import FrameOutputs
from ..frame.hooks import PHOTO_FRAME, EngineFrame
from ..frame.motion import MotionBlur, frame_motion
from ..frame.report import ReportItem, StageTimings
from ..scene.sanity import FlagTally
from ..tracking.luma import LumaFrame
from ..tracking.reference import ReferenceTally
from ..transforms import rvec_tvec_from_matrix
from .avio import RawFrame, VideoFrame
from .i420 import even_box, i420_planes, i420_roi_to_bgr, i420_with_roi

if TYPE_CHECKING:
    from ..compose.layers import Layers
    from ..export.layervideo import LayerSink
    from ..frame.effects import CameraEffects
    from ..frame.hooks import CalibrationState
    from ..frame.session import Session
    from ..lights.suntrack import SunTrack
    from ..plan.planner import FramePlan
    from ..tracking.pose import MarkerPose
    from .temporal import FramePose

__all__ = [
    "FRAME_STAGES",
    "FrameComposer",
    "FrameStats",
    "SessionBackend",
    "even_box",
    "frame_bgr",
    "gray_of",
    "i420_planes",
    "i420_roi_to_bgr",
    "i420_with_roi",
    "writable",
]

#: a decoded frame: planar ``yuv420p`` or BGR (:class:`RawFrame`), or BGR (:class:`VideoFrame`)
Frame: TypeAlias = RawFrame | VideoFrame
#: what the engine pushes with a frame into the pose stream: ``(frame, decode_ms, timings, format, reason)``
#: (``reason``: why the tracker found no pose, or None)
FramePayload: TypeAlias = tuple[Frame, float, dict[str, float], str, str | None]

#: per-frame ``timings_ms`` keys of the JSON Lines report
FRAME_STAGES = (
    "decode",
    "detect",
    "pose",
    "silhouette",
    "volume",
    "render",
    "readback",
    "warp",
    "composite",
    "convert",
    "encode",
    "total",
)


class SessionBackend:
    """Tracking and rendering for the engine, over an :class:`arshadow.frame.session.Session`.

    The only place the engine touches the rendering API. Tracking reads a grey image (the decoder's
    Y plane: no colour conversion for frames that are only tracked).

    Parameters
    ----------
    session : arshadow.frame.session.Session
    tracks : list of arshadow.lights.suntrack.SunTrack
        Sun lights following the frame times (``time_lapse = (start datetime, speed)``); the session
        must have them (:meth:`Session.use_sun_tracks`).
    """

    def __init__(
        self,
        session: Session,
        tracks: Iterable[SunTrack] = (),
        time_lapse: tuple[datetime, float] | None = None,
    ) -> None:
        self.session, self.tracks, self.time_lapse = session, list(tracks), time_lapse
        self.hooks = session.hooks  # arshadow.frame.hooks.EngineHooks: what the engine reaches into
        self.hooks.input_kind = "video"  # its notes say "the video is WxH"
        self.cal: CalibrationState | None = None
        self.recomputes = 0
        self.want_layers: bool | str = False  # set by process_video when the layers are written
        self.last_layers: Layers | None = None  # the last render's layers (with want_layers)

    def start(self, width: int, height: int) -> None:
        """A new video of this size (CalibrationError: the calibration does not fit it)."""
        self.cal = self.hooks.calibration(width, height)
        self.hooks.reset_tracking()  # a video's output never depends on the video before it
        self.hooks.measured_camera = None  # nor its camera effects (measured on its own first tracked frame)
        for tr in self.tracks:
            tr.reset()
        if self.hooks.exposure is not None:  # the exposure match's smoothing starts afresh
            self.hooks.exposure.reset()
        self.recomputes = 0

    def track(
        self, gray: np.ndarray | LumaFrame, timings: dict[str, float]
    ) -> tuple[MarkerPose | None, MarkerNotFoundError | None]:
        """The marker pose in a grey ``(H, W) uint8`` frame, or ``(None, error)``; ``timings`` (the
        frame's dict of :data:`FRAME_STAGES`) gets ``detect`` and ``pose``."""
        st = StageTimings()
        try:
            return self.session.track(gray, timings=st), None
        except MarkerNotFoundError as exc:
            return None, exc
        finally:
            timings["detect"] += st.detect
            timings["pose"] += st.pose

    def tracker_state(self) -> list:
        """:meth:`arshadow.frame.hooks.EngineHooks.tracker_state` at this video's size."""
        assert self.cal is not None  # set by start()
        return self.hooks.tracker_state(self.cal.intrinsics.width, self.cal.intrinsics.height)

    def replay_sun(self, times: Iterable[float]) -> None:
        """Advance the sun tracks' recompute schedule over the frame times ``times`` (seconds) without
        setting lights or counting recomputes: a chunk starts where a run over the frames before it would
        be. Frame by frame, as :meth:`lights_at` does (the same floats)."""
        for time_s in times if self.tracks else ():
            assert self.time_lapse is not None  # sun tracks follow a time-lapse
            when = self.time_lapse[0] + timedelta(seconds=time_s * self.time_lapse[1])
            for tr in self.tracks:
                tr.update(when)

    def lights_at(self, time_s: float) -> list[dict[str, Any]] | None:
        """Set the lights for a frame time (time-lapse); returns the report's ``sun`` list or None."""
        if not self.tracks:
            return None
        assert self.time_lapse is not None  # sun tracks follow a time-lapse
        when = self.time_lapse[0] + timedelta(seconds=time_s * self.time_lapse[1])
        frames = self.session.set_time(when)
        self.recomputes += sum(bool(f.recompute) for f in frames)
        return [
            {
                "time": f.when.isoformat(),
                "zenith_deg": round(f.position.zenith_deg, 5),
                "azimuth_deg": round(f.position.azimuth_deg, 5),
                "above_horizon": bool(f.above_horizon),
                "recompute": bool(f.recompute),
                "stale_deg": round(f.stale_deg, 5),
            }
            for f in frames
        ]

    def plan(self, cam_from_marker: np.ndarray, width: int, height: int) -> FramePlan:
        """The frame's :class:`arshadow.plan.FramePlan` at the marker pose ``cam_from_marker`` (its ``roi``:
        the only pixels the compositor reads and changes)."""
        return self.session.plan(cam_from_marker, width, height)

    def exposure_region(
        self, cam_from_marker: np.ndarray, width: int, height: int, marker: MarkerPose | None = None
    ) -> tuple | None:
        """The pixels the exposure match reads (:meth:`arshadow.frame.hooks.EngineHooks.exposure_region`), or None;
        ``marker``: the frame's tracked pose (its marker id)."""
        return self.hooks.exposure_region(cam_from_marker, width, height, marker)

    @property
    def measures_exposure(self) -> bool:
        """The session's exposure match is on (:attr:`arshadow.frame.hooks.EngineHooks.exposure`)."""
        return self.hooks.exposure is not None

    def observe_exposure(self, bgr: np.ndarray, cam_from_marker: np.ndarray, marker: MarkerPose | None) -> None:
        """:meth:`arshadow.frame.hooks.EngineHooks.observe_exposure` (a chunk's primer frame)."""
        self.hooks.observe_exposure(bgr, cam_from_marker, marker)

    def exposure_gap(self) -> None:
        """:meth:`arshadow.frame.hooks.EngineHooks.exposure_gap` (a frame without the marker)."""
        self.hooks.exposure_gap()

    def motion(self, fp: FramePose, before: FramePose | None, after: FramePose | None) -> MotionBlur | None:
        """The decided frame ``fp``'s motion blur (:func:`arshadow.frame.motion.frame_motion`: its neighbours'
        poses, each used when tracked and one frame away; none for a held pose), None when off (camera effects
        or motion blur off)."""
        o, s = self.session.options, self.session
        if o.camera_effects != "on" or o.motion_blur != "on" or fp.cam_from_marker is None:
            return None
        assert self.cal is not None  # set by start()
        if fp.status != "ok":
            return MotionBlur(shutter=float(o.shutter), source="none: a held pose (it does not follow the camera)")
        index = cast(FramePayload, fp.payload)[0].index

        def near(n: FramePose | None) -> tuple[np.ndarray, int] | None:
            if n is None or n.status != "ok" or n.cam_from_marker is None:
                return None
            k = abs(cast(FramePayload, n.payload)[0].index - index)
            return (s.ground_camera(n.cam_from_marker), k) if k == 1 else None

        cfw = s.ground_camera(fp.cam_from_marker)
        return frame_motion(self.cal.intrinsics, s.geometry.corners, cfw, near(before), near(after), o.shutter)

    def camera_unmeasured(self, marker: MarkerPose | None) -> bool:
        """Whether this frame (its tracked ``marker``, None: not in view) is the one the camera's blur and
        noise are to be measured on (``--camera-effects on``, not measured yet)."""
        s = self.session
        return marker is not None and s.options.camera_effects == "on" and s.camera_effects is None

    def measure_camera(self, bgr: np.ndarray, marker: MarkerPose) -> None:
        """Measure the camera's blur and noise on the whole frame ``bgr (H, W, 3) uint8`` (once a video)."""
        self.hooks.camera_effects(bgr, marker)

    def use_camera(self, camera: CameraEffects | None) -> None:
        """This video's camera blur and noise as measured elsewhere (:func:`arshadow.video.engine.first_camera`:
        a chunk of a video, whose first tracked frame the chunk need not hold); after :meth:`start`."""
        self.hooks.measured_camera = camera

    def grown(self, roi: Sequence[int], motion: MotionBlur | None) -> tuple[int, int, int, int]:
        """``roi`` grown by the blurs' reach (``motion``'s, if any, and the measured camera blur's), within the
        frame."""
        assert self.cal is not None  # set by start()
        intr = self.cal.intrinsics
        return touched_roi(roi, self.session.camera_effects, motion, intr.width, intr.height)

    def render(
        self,
        bgr: np.ndarray,
        cam_from_marker: np.ndarray | None,
        want_mask: bool,
        timings: dict[str, float],
        plan: FramePlan | None = None,
        frame: EngineFrame = PHOTO_FRAME,
    ) -> tuple[np.ndarray | None, ReportItem]:
        """Composite into ``bgr`` (modified in place), at the marker pose ``cam_from_marker`` or carrying out
        ``plan``; returns ``(mask or None, the frame's report item)``; ``timings`` gets the render stages.
        ``frame``: the frame's tracked marker (the exposure match reads its paper; none in view: a held pose,
        the exposure match keeps the last gain) and its motion blur (:meth:`motion`)."""
        outputs = FrameOutputs(want_mask=want_mask, out=bgr)
        kw: dict[str, Any] = {"outputs": outputs, "layers": self.want_layers, "frame": frame}
        if plan is not None:
            res = self.hooks.render(bgr, plan=plan, **kw)
        else:
            res = self.hooks.render(bgr, cam_from_marker, **kw)
        self.last_layers = res.layers
        for k, v in res.timings.as_dict().items():
            if k != "total":
                timings[k] += v
        return res.mask, res.item

    @property
    def notes(self) -> list[str]:
        return list(self.session.notes or [])


def gray_of(frame: Frame, height: int, colour: bool = False) -> np.ndarray | LumaFrame:
    """The grey image the tracker reads: for a planar ``yuv420p`` frame, its Y plane as a
    :class:`arshadow.tracking.luma.LumaFrame` (expanded from limited to full range where the tracker reads
    it: the Y plane itself lost real markers, the real-footage work), else OpenCV's BGR -> grey ``(H, W) uint8``.
    ``colour``: a ``yuv420p`` frame's BGR -> grey instead (the photo path's grey; the engine's retry when
    the Y plane shows no marker)."""
    if getattr(frame, "format", "bgr24") == "yuv420p":
        if colour:
            grey: np.ndarray = cv2.cvtColor(cv2.cvtColor(frame.image, cv2.COLOR_YUV2BGR_I420), cv2.COLOR_BGR2GRAY)
            return grey
        return LumaFrame(frame.image[:height])
    grey = cv2.cvtColor(frame.image, cv2.COLOR_BGR2GRAY)
    return grey


def frame_bgr(img: np.ndarray, fmt: str = "bgr24") -> np.ndarray:
    """The whole frame ``img`` (its pixel format ``fmt``) as ``(H, W, 3) uint8`` BGR, what the camera's blur
    and noise are measured on (:meth:`SessionBackend.measure_camera`; the compositor and
    :func:`arshadow.video.engine.first_camera` alike): a ``yuv420p`` frame by :func:`i420_roi_to_bgr` over the
    whole frame, a BGR frame copied."""
    if fmt != "yuv420p":
        return np.array(img)
    h, w = img.shape[0] * 2 // 3, img.shape[1]
    bgr = np.zeros((h, w, 3), np.uint8)
    i420_roi_to_bgr(img, bgr, (0, 0, w, h))
    return bgr


class FrameStats(TypedDict):
    """A video's frame counts (:attr:`FrameComposer.stats`)."""

    frames: int
    frames_ok: int
    frames_held: int
    frames_no_marker: int
    swapped: int
    longest_gap: int
    longest_gap_start: int | None


class FrameComposer:
    """Turns each decided frame (:class:`arshadow.video.temporal.FramePose`) into the encode thread's job.

    Parameters
    ----------
    backend : SessionBackend
    name : str
        The input, as the report names it.
    out_video, out_mask : str or Path, and str or Path or None
        The outputs the report items name.
    size : (int, int)
        ``(width, height)``.
    want_mask : bool

    Attributes
    ----------
    stats : dict
        ``frames``, ``frames_ok``, ``frames_held``, ``frames_no_marker``, ``swapped``, ``longest_gap``
        (most frames in a row not tracked) and ``longest_gap_start`` (its first frame, None without a gap).
    stage_ms : dict
        Per stage of :data:`FRAME_STAGES`, every frame's milliseconds (``encode`` filled by the encoder).
    """

    def __init__(
        self,
        backend: SessionBackend,
        name: str,
        out_video: str | PathLike[str],
        out_mask: str | PathLike[str] | None,
        size: tuple[int, int],
        want_mask: bool,
    ) -> None:
        self.backend, self.name = backend, name
        self.out_video, self.out_mask = str(out_video), None if out_mask is None else str(out_mask)
        self.W, self.H = size
        self.want_mask = want_mask
        self.stats: FrameStats = {
            "frames": 0,
            "frames_ok": 0,
            "frames_held": 0,
            "frames_no_marker": 0,
            "swapped": 0,
            "longest_gap": 0,
            "longest_gap_start": None,
        }
        self._gap: tuple[int, int | None] = (0, None)  # (length, first frame) of the current run of frames not tracked
        self.flags = FlagTally()  # flagged poses: one warning line for the video
        self.refs = ReferenceTally()  # the reference marker of each tracked frame: a change is warned of
        self.stage_ms: dict[str, list[float]] = {k: [] for k in FRAME_STAGES}
        # (H, W, 3) uint8: BGR of the current frame inside its ROI (yuv420p input)
        self._bgr: np.ndarray | None = None
        #: an :class:`arshadow.export.layervideo.LayerSink` getting every frame's layers, or None
        self.layer_sink: LayerSink | None = None

    def compose(
        self, fp: FramePose, before: FramePose | None = None, after: FramePose | None = None
    ) -> tuple[np.ndarray, str, np.ndarray | None, ReportItem, dict[str, Any]]:
        """One decided frame -> ``(image, format, mask or None, ReportItem, JSON Lines record)``.

        ``fp.payload`` is ``(frame, decode_ms, timings, format[, reason])`` as pushed by the engine
        (``reason``: why the tracker found no pose, the record's ``not_tracked``); ``before``, ``after``: the
        frames decided just before and after it, if any (their poses give the motion blur,
        :meth:`SessionBackend.motion`).
        """
        fr, dec_ms, timings, fmt, *rest = cast(FramePayload, fp.payload)
        self._count_gap(fr.index, fp.status == "ok")
        img = fr.image
        sun = self.backend.lights_at(fr.time_s)
        mask = None
        if fp.status == "no_marker":
            self.backend.exposure_gap()
            item = ReportItem(input=self.name, status=fp.status, error="no marker found")
            self.stats["frames_no_marker"] += 1
            if self.want_mask:
                mask = np.zeros((self.H, self.W), np.uint8)
            if self.layer_sink is not None:
                self.layer_sink.write(None)
        else:
            assert fp.cam_from_marker is not None  # "ok" or "held"
            frame = EngineFrame(fp.raw, fp.raw is not None, self.backend.motion(fp, before, after))
            img, mask, item = self._render(fp.cam_from_marker, img, fmt, timings, frame)  # the one item
            item.input, item.status = self.name, fp.status
            self._pose_fields(item, fp)
            if fp.raw is not None:
                self.refs.add(fr.index, fp.reference_id)
            if fp.raw is not None:
                self.stats["frames_ok"] += 1
            else:
                self.stats["frames_held"] += 1
            self.stats["swapped"] += int(fp.swapped)
        item.output, item.mask = self.out_video, self.out_mask
        item.frame, item.time_s, item.sun = fr.index, round(fr.time_s, 6), sun
        self.flags.add(fr.index, item.flag_reasons)  # reasons of the tracked pose (None when held / missing)
        self._finish_timings(item, timings, dec_ms)
        item.notes = self.backend.notes or None
        self.stats["frames"] += 1
        rec = frame_record(fr, item, sun)
        if fp.status != "ok" and rest and rest[0]:
            rec["not_tracked"] = str(rest[0])
        return img, fmt, mask, item, rec

    def prime(self, fp: FramePose) -> None:
        """A decided frame before a chunk's start (not composited): its paper is measured for the exposure
        match's smoothing (:meth:`SessionBackend.observe_exposure`) when the marker is in it, else counted as
        a frame without a measurement, as rendering it would."""
        if not self.backend.measures_exposure:
            return
        if fp.status != "ok" or fp.raw is None:
            self.backend.exposure_gap()
            return
        fr, fmt = cast(FramePayload, fp.payload)[0], cast(FramePayload, fp.payload)[3]
        assert fp.cam_from_marker is not None  # status "ok"
        if self.backend.plan(fp.cam_from_marker, self.W, self.H).empty:
            return  # a frame with nothing to draw measures nothing when it is rendered either
        region = self.backend.exposure_region(fp.cam_from_marker, self.W, self.H, fp.raw)
        if region is None:  # the paper is not in view (its measurement would fail)
            self.backend.exposure_gap()
            return
        if fmt == "yuv420p":
            bgr = self._frame_buffer()
            i420_roi_to_bgr(fr.image, bgr, region)
        else:
            bgr = fr.image
        self.backend.observe_exposure(bgr, fp.cam_from_marker, fp.raw)

    def _count_gap(self, index: int, tracked: bool) -> None:
        n, start = self._gap
        self._gap = (0, None) if tracked else (n + 1, index if start is None else start)
        if self._gap[0] > self.stats["longest_gap"]:
            self.stats["longest_gap"], self.stats["longest_gap_start"] = self._gap

    @staticmethod
    def _pose_fields(item: ReportItem, fp: FramePose) -> None:
        """The report's pose keys: the tracked (raw) pose and the one rendered with (smoothed / held)."""
        if fp.raw is not None:
            item.set_pose(fp.raw)
        assert fp.cam_from_marker is not None  # a frame with a pose (tracked or held)
        r, t = rvec_tvec_from_matrix(fp.cam_from_marker)
        item.raw = (
            None
            if fp.raw is None
            else {
                "rvec": np.asarray(fp.raw.rvec, float).ravel().tolist(),
                "tvec": np.asarray(fp.raw.tvec, float).ravel().tolist(),
            }
        )
        item.rvec, item.tvec = r.tolist(), t.tolist()
        item.reference_id = fp.reference_id
        item.pose_choice = "temporal (alternative IPPE solution)" if fp.swapped else "error"

    def decision(self, fp: FramePose) -> dict[str, Any]:
        """The pose decision of a frame that is not composited (a chunk's look-ahead past its end):
        ``frame``, ``status``, ``raw``, ``rvec``, ``tvec``, ``pose_choice`` as its JSON Lines record has them."""
        item = ReportItem(input=self.name, status=fp.status)
        if fp.status != "no_marker":
            self._pose_fields(item, fp)
        return {
            "frame": cast(FramePayload, fp.payload)[0].index,
            "status": item.status,
            "raw": item.raw,
            "rvec": item.rvec,
            "tvec": item.tvec,
            "pose_choice": item.pose_choice,
        }

    def _render(
        self,
        cam_from_marker: np.ndarray,
        img: np.ndarray,
        fmt: str,
        timings: dict[str, float],
        frame: EngineFrame = PHOTO_FRAME,
    ) -> tuple[np.ndarray, np.ndarray | None, ReportItem]:
        """Composite at the (decided) marker pose ``cam_from_marker``; returns the frame in its own format, the mask and the report
        item of :meth:`arshadow.frame.session.Session.render`. ``frame``: the frame's tracked pose (None: held)
        and its motion blur.

        A ``yuv420p`` frame is converted to BGR only inside the plan's ROI grown by the blurs' reach (the
        camera's and an applied motion blur's, :meth:`SessionBackend.grown`; even-aligned; into a buffer kept
        for the video): the compositor reads and writes no pixel outside it, and the result goes back into
        the planes inside it only (:func:`i420_with_roi`)."""
        marker, motion = frame.marker, frame.motion
        if fmt != "yuv420p":
            tc = time.perf_counter()
            bgr = np.array(img)
            timings["convert"] += (time.perf_counter() - tc) * 1e3
            mask, item = self.backend.render(bgr, cam_from_marker, self.want_mask, timings, frame=frame)
            if self.layer_sink is not None:
                self.layer_sink.write(self.backend.last_layers)
            return bgr, mask, item
        plan = self.backend.plan(cam_from_marker, self.W, self.H)
        tc = time.perf_counter()
        bgr = self._frame_buffer()
        if self.backend.camera_unmeasured(marker):  # the optics are read on the whole frame, once a video
            assert marker is not None  # camera_unmeasured: a tracked marker
            self.backend.measure_camera(frame_bgr(img, fmt), marker)
        # what the compositor may write: the ROI grown by the blurs' reach (the camera's, and the motion's
        # when it is applied); the ROI alone without them
        region = self.backend.grown(plan.roi, motion if motion is not None and motion.active else None)
        i420_roi_to_bgr(img, bgr, region)
        if (
            marker is not None
            and not plan.empty
            and (paper := self.backend.exposure_region(cam_from_marker, self.W, self.H, marker)) is not None
        ):
            i420_roi_to_bgr(img, bgr, paper)  # the exposure match reads the marker's paper, often outside the ROI
        timings["convert"] += (time.perf_counter() - tc) * 1e3
        mask, item = self.backend.render(bgr, cam_from_marker, self.want_mask, timings, plan=plan, frame=frame)
        if self.layer_sink is not None:
            self.layer_sink.write(self.backend.last_layers)
        tc = time.perf_counter()
        img = i420_with_roi(img, bgr, region, out=writable(img))
        timings["convert"] += (time.perf_counter() - tc) * 1e3
        return img, mask, item

    def _frame_buffer(self) -> np.ndarray:
        """The video's ``(H, W, 3) uint8`` BGR buffer a ``yuv420p`` frame's regions are converted into (made once)."""
        if self._bgr is None:
            self._bgr = np.zeros((self.H, self.W, 3), np.uint8)
        return self._bgr

    def _finish_timings(self, item: ReportItem, timings: dict[str, float], dec_ms: float) -> None:
        timings["decode"] = dec_ms
        timings["total"] = sum(v for k, v in timings.items() if k not in ("total", "decode", "encode"))
        item.timings_ms = {k: round(v, 3) for k, v in timings.items()}
        for k in FRAME_STAGES:
            if k in timings and k != "encode":
                self.stage_ms[k].append(timings[k])


def writable(a: np.ndarray) -> np.ndarray | None:
    """``a`` made writable in place when its memory allows it (a decoded frame is the pipeline's own copy,
    marked read-only only against accidents: the frame job writes its ROI back into it once the frame is
    tracked and rendered, instead of copying the whole frame), else None.

    >>> a = np.zeros(3, np.uint8); a.setflags(write=False)
    >>> writable(a) is a, writable(np.frombuffer(b"abc", np.uint8))
    (True, None)
    """
    try:
        a.setflags(write=True)
    except ValueError:
        return None
    return a


def frame_record(fr: Frame, item: ReportItem, sun: list[dict[str, Any]] | None) -> dict[str, Any]:
    """One frame's JSON Lines record (``timings_ms["encode"]`` is filled in by the encoder).

    ``reference_id``: the marker whose frame the pose is in (the tracked pose's, a held frame's last one;
    None for a board or without a pose); ``pose_flagged`` / ``flag_reasons``: the tracked pose's flags
    (false / [] without one), ``pose_notes`` its report-only reasons (the cluster and flags work);
    ``motion_blur``: the frame's motion blur values (:meth:`arshadow.frame.motion.MotionBlur.report`), only
    with camera effects and motion blur on."""
    line: dict[str, Any] = {
        "frame": fr.index,
        "time_s": round(fr.time_s, 6),
        "status": item.status,
        "reference_id": getattr(item, "reference_id", None),
        "marker_ids": item.marker_ids,
        "rvec": item.rvec,
        "tvec": item.tvec,
        "raw": item.raw,
        "reprojection_error_px": item.reprojection_error_px,
        "pose_ambiguity": item.pose_ambiguity,
        "pose_choice": item.pose_choice,
        "pose_flagged": bool(item.pose_flagged),
        "flag_reasons": list(item.flag_reasons or []),
        "pose_notes": list(item.pose_notes or []),
        "mode": item.mode,
        "timings_ms": item.timings_ms,
    }
    if sun is not None:
        line["sun"] = sun
    if item.plan and "motion_blur" in item.plan:  # --camera-effects on, --motion-blur on: the frame's values
        line["motion_blur"] = item.plan["motion_blur"]
    return line
