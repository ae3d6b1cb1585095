"""The preview's renderer: one :class:`arshadow.frame.session.Session` on one thread renders what the page asks.

A request is the page's whole control state (:mod:`arshadow.preview.edit`), checked on the server thread
that received it (a bad one is answered 400 before it queues), then run by a
:class:`arshadow.preview.worker.LatestWins` thread that owns the session and its OpenGL context: only the
newest waiting request runs. The session is the one ``arshadow render`` uses: what the page shows is what
``render`` writes from the saved scene file. Moving, turning or scaling the object keeps the session
(:meth:`arshadow.frame.session.Session.set_model`), a light change too (``set_lights``); any other change (opacity,
soft samples, the object shown or not, the measured light) makes a new session on the same context.
"""

from __future__ import annotations

import dataclasses
import logging
import os
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import cv2
import numpy as np

from ..errors import ImageError, MarkerNotFoundError
from ..frame.execute import FrameOutputs
from ..frame.hooks import EngineFrame
from ..frame.report import ReportItem, jsonable
from ..io import read_image, write_bytes
from ..scene.spec import SCENE_KEYS, scene_from_dict
from ..transforms import invert_rigid
from .draft import draft_pose, ground_motion, moved_lights
from .edit import ControlError, apply_controls, command_line, controls_of, ground_point, relative_paths
from .worker import LatestWins

__all__ = ["Media", "PreviewEngine", "RenderRequest", "VIDEO_SUFFIXES"]

log = logging.getLogger(__name__)

#: inputs read as videos (frame slider); anything else is a photo
VIDEO_SUFFIXES = (".mp4", ".mov", ".mkv", ".avi", ".webm", ".m4v")
#: decoded video frames kept (a frame slider going back and forth)
FRAME_CACHE = 8
#: rendered images kept for the page to fetch (``GET /api/image/ID/KIND``)
KEEP_IMAGES = 8


def _image_url(image_id: int, kind: str) -> str:
    return f"/api/image/{image_id}/{kind}"


class Media:
    """The one photo or video the preview was given; frames by index (nothing else is ever opened).

    Raises
    ------
    ImageError
        Unreadable photo or video.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = str(path)
        self.name = Path(self.path).name
        self.is_video = self.path.lower().endswith(VIDEO_SUFFIXES)
        self._frames: OrderedDict[int, np.ndarray] = OrderedDict()
        self._lock = threading.Lock()
        if self.is_video:
            cap = cv2.VideoCapture(self.path)
            ok, first = cap.read() if cap.isOpened() else (False, None)
            n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) if ok else 0
            cap.release()
            if not ok or first is None:
                raise ImageError(f"{self.path}: cannot read the video")
            self.count = max(n, 1)
            self._frames[0] = first
        else:
            self.count = 1
            self._frames[0] = read_image(self.path)
        self.height, self.width = self._frames[0].shape[:2]

    def frame(self, index: int) -> np.ndarray:
        """Frame ``index`` (0-based), ``(H, W, 3) uint8`` BGR as stored."""
        with self._lock:
            img = self._frames.get(index)
            if img is not None:
                self._frames.move_to_end(index)
                return img
            cap = cv2.VideoCapture(self.path)
            cap.set(cv2.CAP_PROP_POS_FRAMES, index)
            ok, img = cap.read()
            cap.release()
            if not ok:
                raise ImageError(f"{self.path}: cannot read frame {index}")
            self._frames[index] = img
            while len(self._frames) > FRAME_CACHE:
                self._frames.popitem(last=False)
            return img


@dataclass(frozen=True)
class RenderRequest:
    """One checked request: the scene to render (job-file keys), the frame, and the drag's pixel."""

    scene: dict
    frame: int = 0
    drag_to: tuple | None = None
    want_mask: bool = False
    #: a frame while the pointer moves: may be a draft (:mod:`arshadow.preview.draft`)
    draft: bool = False


def _bmp(img: np.ndarray) -> bytes:
    """The image as BMP bytes: lossless, so the page shows the composite's exact pixels (a 720p PNG takes
    ~100 ms to encode here, a BMP ~2 ms; the bytes only cross the loopback)."""
    ok, buf = cv2.imencode(".bmp", img)
    if not ok:  # pragma: no cover - OpenCV encodes any uint8 image
        raise ImageError("cannot encode the preview image")
    return buf.tobytes()


class PreviewEngine:
    """Renders the page's requests with one session on one thread; saves the last rendered scene.

    Parameters
    ----------
    media : Media
    base : dict
        The starting scene (job-file keys, absolute paths).
    scene_out : path
        Where ``save`` writes the scene file (the page cannot choose it).
    own_lights : list of str, optional
        The lights the page's azimuth / elevation move (see :func:`arshadow.preview.edit.apply_controls`).
    """

    def __init__(
        self, media: Media, base: dict, scene_out: str | os.PathLike[str], own_lights: list | None = None
    ) -> None:
        self.media, self.base, self.own_lights = media, dict(base), own_lights
        self.scene_out = Path(scene_out).resolve()
        self._session: Any = None
        self._spec: Any = None
        self._ctx: Any = None
        self._poses: dict[int, Any] = {}
        self._last: dict | None = None  # the scene of the last image shown
        self._draft_session: Any = None  # drafts' session (arshadow.preview.draft), its spec's key, its frame
        self._draft_key: Any = None
        self._draft_frame: int | None = None
        self._last_lock = threading.Lock()
        self._images: OrderedDict[int, dict[str, bytes]] = OrderedDict()  # the last images, by id
        self._image_id = 0
        self.worker = LatestWins(self._run, on_stop=self._release)
        scene_from_dict(self.base)  # a bad starting scene: one usage error now

    # -- requests (any server thread) ---------------------------------------------------------------
    def request(self, body: Any) -> RenderRequest:
        """Check a render request's JSON body: ``{"controls": {...}, "frame": N, "drag_to": [u, v],
        "mask": bool}``.

        Raises
        ------
        ControlError
            Anything malformed (answered 400).
        """
        if not isinstance(body, dict):
            raise ControlError("the request body is not a JSON object")
        unknown = sorted(set(body) - {"controls", "frame", "drag_to", "mask", "draft", "seq"})
        if unknown:
            raise ControlError(f"unknown request key(s) {', '.join(map(repr, unknown))}")
        scene = apply_controls(self.base, body.get("controls"), own_lights=self.own_lights)
        frame = body.get("frame", 0)
        if not isinstance(frame, int) or isinstance(frame, bool) or not 0 <= frame < self.media.count:
            raise ControlError(f"frame {frame!r}: expected a whole number in [0, {self.media.count - 1}]")
        drag = body.get("drag_to")
        if drag is not None:
            ok = isinstance(drag, list) and len(drag) == 2
            ok = ok and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in drag)
            if not ok or not all(np.isfinite(drag)):
                raise ControlError(f"drag_to {drag!r}: expected two finite pixel coordinates [u, v]")
            if not (-0.5 <= drag[0] <= self.media.width - 0.5 and -0.5 <= drag[1] <= self.media.height - 0.5):
                raise ControlError(f"drag_to {drag!r}: outside the {self.media.width}x{self.media.height} image")
            drag = (float(drag[0]), float(drag[1]))
        flags = {k: body.get(k, False) for k in ("mask", "draft")}
        for k, v in flags.items():
            if not isinstance(v, bool):
                raise ControlError(f"{k} {v!r}: expected true or false")
        scene_from_dict(scene)  # a scene the spec refuses: 400 here, not on the render thread
        return RenderRequest(scene, frame, drag, flags["mask"], flags["draft"])

    def render(self, req: RenderRequest, timeout: float = 120.0) -> dict:
        """Run ``req`` (newest wins: raises :class:`arshadow.preview.worker.Superseded` when dropped)."""
        t0 = time.perf_counter()
        out: dict = self.worker.submit((req, t0)).result(timeout)
        return out

    def close(self) -> None:
        self.worker.close()

    # -- the render thread --------------------------------------------------------------------------
    def _session_for(self, spec: Any, move: bool = True) -> Any:
        """The session for ``spec``: the current one moved / relit when only the model or lights differ
        (``move`` False: left as it is then; the caller moves it once it knows where)."""
        from ..frame.session import Session

        cur = self._spec
        if self._session is None or spec.replace(model=cur.model, lights=cur.lights) != cur:
            if self._session is not None:
                self._session.close()
                self._session = self._spec = None  # a scene that fails to load leaves no closed session behind
            self._session = Session(spec, context=self._context())
        elif not move:
            return self._session
        else:
            if spec.model != cur.model:
                self._session.set_model(spec.model)
            if spec.lights != cur.lights:
                self._session.set_lights(list(spec.lights))
        self._spec = spec
        return self._session

    def _context(self) -> Any:
        if self._ctx is None:
            from ..gl.context import create_context  # the one context, made on this (the render) thread

            self._ctx = create_context()
        return self._ctx

    def _pose(self, session: Any, index: int, image: np.ndarray) -> Any:
        pose = self._poses.get(index)
        if pose is None:
            pose = self._poses[index] = session.track(image)
        return pose

    def _draft(self, spec: Any, image: np.ndarray, index: int, pose: Any, want_mask: bool) -> Any:
        """Render ``spec`` as a draft (:mod:`arshadow.preview.draft`), or None when it is not a ground
        motion of the model the draft session holds or of the exact session's."""
        from ..frame.session import Session
        from ..lights.spec import parse_light

        # the draft session tracks like a video's (track_roi); its outline is the exact render's (a photo's:
        # the planner's auto decision would take a video's)
        outline = "on" if spec.options.outline_aa == "auto" else spec.options.outline_aa
        key = spec.replace(lights=(), options=dataclasses.replace(spec.options, track_roi=True, outline_aa=outline))
        motion = None
        if self._draft_session is not None and key.replace(model=self._draft_key.model) == self._draft_key:
            motion = ground_motion(self._draft_key.model, spec.model)
        if motion is None:
            motion = ground_motion(self._spec.model, spec.model)
            if motion is None:
                return None
            if self._draft_session is not None:
                self._draft_session.close()
                self._draft_session = None
            self._draft_key = key.replace(model=self._spec.model)
            self._draft_session = Session(self._draft_key.replace(lights=spec.lights), context=self._context())
            self._draft_frame = None
        s = self._draft_session
        if self._draft_frame != index:  # the exposure the drafts keep: this frame's, at the real camera
            s.hooks.observe_exposure(image, pose.cam_from_world, pose)
            self._draft_frame = index
        lights = [parse_light(x) if isinstance(x, str) else x for x in spec.lights]
        s.set_lights(moved_lights(lights, invert_rigid(motion)))
        mfg = None if s.ground.is_marker else s.ground.marker_from_ground
        cfm = draft_pose(s.ground_camera(pose.cam_from_world), motion, mfg)
        item = ReportItem(input=self.media.name)
        outputs = FrameOutputs(want_mask=want_mask, item=item)
        return s.hooks.render(image, cfm, outputs=outputs, frame=EngineFrame(marker=pose, seen=False))

    def _run(self, job: tuple) -> dict:
        req, t_submit = job
        t0 = time.perf_counter()
        scene = {k: (list(v) if isinstance(v, list) else v) for k, v in req.scene.items()}
        image = self.media.frame(req.frame)
        session = self._session_for(scene_from_dict(scene), move=False)  # moved below, once
        try:
            pose = self._pose(session, req.frame, image)
        except MarkerNotFoundError as exc:
            iid = self._store({"composite": _bmp(image)})
            return {
                "image": _image_url(iid, "composite"),
                "image_id": iid,
                "error": str(exc),
                "scene": scene,
                "controls": controls_of(scene),
            }
        H, W = image.shape[:2]
        cal = session.hooks.calibration(W, H)
        cfw = session.ground_camera(pose.cam_from_world)
        if req.drag_to is not None:
            g = ground_point(cal.intrinsics, cfw, req.drag_to)
            if g is None:
                raise ControlError(f"drag_to {list(req.drag_to)}: that pixel's ray does not meet the ground")
            scene["place"] = [float(g[0]), float(g[1]), float(scene["place"][2])]
        spec = scene_from_dict(scene)
        t1 = time.perf_counter()
        res = self._draft(spec, image, req.frame, pose, req.want_mask) if req.draft else None
        draft = res is not None
        if res is None:
            res = self._session_for(spec).render(image, pose, name=self.media.name, want_mask=req.want_mask)
        t2 = time.perf_counter()
        images = {"composite": _bmp(res.composite)}
        if req.want_mask and res.mask is not None:
            images["mask"] = _bmp(res.mask)
        iid = self._store(images)
        t3 = time.perf_counter()
        with self._last_lock:
            self._last = {"scene": scene, "frame": req.frame, "draft": draft}
        length = float(session.scene.tracker.get("marker_length") or 0.05)
        axes = cal.intrinsics.project(np.array([[0, 0, 0], [length, 0, 0], [0, length, 0], [0, 0, length]], float), cfw)
        anchor = cal.intrinsics.project(np.asarray([scene["place"]], float), cfw)[0]
        item = res.item.to_dict()
        return cast(
            dict,
            jsonable(
                {
                    "image": _image_url(iid, "composite"),
                    "mask": _image_url(iid, "mask") if "mask" in images else None,
                    "image_id": iid,
                    "scene": scene,
                    "controls": controls_of(scene),
                    "frame": req.frame,
                    "draft": draft,
                    "axes_px": axes.tolist(),
                    "anchor_px": anchor.tolist(),
                    "roi": item.get("roi"),
                    "report": item,
                    "decisions": [[d.name, d.value, d.reason] for d in res.plan.decisions],
                    "server_ms": {
                        "wait": round((t0 - t_submit) * 1e3, 3),
                        "prepare": round((t1 - t0) * 1e3, 3),
                        "render": round((t2 - t1) * 1e3, 3),
                        "encode": round((t3 - t2) * 1e3, 3),
                        "total": round((t3 - t_submit) * 1e3, 3),
                    },
                }
            ),
        )

    def _store(self, images: dict[str, bytes]) -> int:
        with self._last_lock:
            self._image_id += 1
            self._images[self._image_id] = images
            while len(self._images) > KEEP_IMAGES:
                self._images.popitem(last=False)
            return self._image_id

    def image(self, image_id: int, kind: str = "composite") -> bytes | None:
        """The BMP bytes of a rendered image (``kind`` ``"composite"`` or ``"mask"``), or None when it is
        not one of the last :data:`KEEP_IMAGES` (any thread)."""
        with self._last_lock:
            return self._images.get(int(image_id), {}).get(kind)

    def _release(self) -> None:
        if self._draft_session is not None:
            self._draft_session.close()
            self._draft_session = None
        if self._session is not None:
            self._session.close()
            self._session = None
        if self._ctx is not None:
            self._ctx.release()
            self._ctx = None

    # -- save (any thread; no GL) -------------------------------------------------------------------
    def save(self) -> dict:
        """Write the scene of the last image shown to :attr:`scene_out` (YAML, the job-file format, paths
        relative to its folder; atomically) and say the equivalent command lines.

        Raises
        ------
        ControlError
            Nothing rendered yet.
        """
        import yaml

        with self._last_lock:
            last = None if self._last is None else dict(self._last)
        if last is None:
            raise ControlError("nothing to save yet: no image was rendered")
        folder = self.scene_out.parent
        d = relative_paths(last["scene"], folder)
        d = {k: d[k] for k in SCENE_KEYS if k in d}
        text = yaml.safe_dump(d, sort_keys=False, default_flow_style=None)
        write_bytes(self.scene_out, text.encode("utf-8"))
        media = os.path.relpath(self.media.path)
        cmd = command_line(relative_paths(last["scene"], os.getcwd()), media, self.media.is_video)
        out = "out/"
        return {
            "path": str(self.scene_out),
            "scene": text,
            "command": cmd,
            "batch_command": f"arshadow batch {media} --config {os.path.relpath(self.scene_out)} -o {out}",
        }
