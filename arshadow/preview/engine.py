"""The preview's renderer: one :class:`arshadow.session.Session` on one thread renders what the page asks.

A request is the page's whole control state (:mod:`arshadow.preview.edit`), checked on the server thread
that received it (a bad one is answered 400 before it queues), then run by a
:class:`arshadow.preview.worker.LatestWins` thread that owns the session and its OpenGL context: only the
newest waiting request runs. The session is the one ``arshadow render`` uses: what the page shows is what
``render`` writes from the saved scene file. Moving, turning or scaling the object keeps the session
(:meth:`arshadow.session.Session.set_model`), a light change too (``set_lights``); any other change (opacity,
soft samples, the object shown or not, the measured light) makes a new session on the same context.
"""

from __future__ import annotations

import base64
import logging
import os
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from ..errors import ImageError, MarkerNotFoundError
from ..io import read_image, write_bytes
from ..report import jsonable
from ..scene import SCENE_KEYS, scene_from_dict
from .edit import ControlError, apply_controls, command_line, controls_of, ground_point, relative_paths
from .worker import LatestWins

__all__ = ["Media", "PreviewEngine", "RenderRequest", "VIDEO_SUFFIXES"]

log = logging.getLogger(__name__)

#: inputs read as videos (frame slider); anything else is a photo
VIDEO_SUFFIXES = (".mp4", ".mov", ".mkv", ".avi", ".webm", ".m4v")
#: decoded video frames kept (a frame slider going back and forth)
FRAME_CACHE = 8


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
            if not ok:
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


def _data_url(img: np.ndarray) -> str:
    """The image as a lossless BMP data URL: the page shows the composite's exact pixels (a 720p PNG takes
    ~100 ms to encode here, a BMP ~5 ms, and the bytes only cross the loopback)."""
    ok, buf = cv2.imencode(".bmp", img)
    if not ok:  # pragma: no cover - OpenCV encodes any uint8 image
        raise ImageError("cannot encode the preview image")
    return "data:image/bmp;base64," + base64.b64encode(buf.tobytes()).decode("ascii")


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
        self._last_lock = threading.Lock()
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
        unknown = sorted(set(body) - {"controls", "frame", "drag_to", "mask", "seq"})
        if unknown:
            raise ControlError(f"unknown request key(s) {', '.join(map(repr, unknown))}")
        scene = apply_controls(self.base, body.get("controls"), own_lights=self.own_lights)
        frame = body.get("frame", 0)
        if not isinstance(frame, int) or isinstance(frame, bool) or not 0 <= frame < self.media.count:
            raise ControlError(f"frame {frame!r}: expected a whole number in [0, {self.media.count - 1}]")
        drag = body.get("drag_to")
        if drag is not None:
            ok = isinstance(drag, list) and len(drag) == 2 and all(isinstance(x, (int, float)) for x in drag)
            if not ok or isinstance(drag[0], bool) or not all(np.isfinite(drag)):
                raise ControlError(f"drag_to {drag!r}: expected two finite pixel coordinates [u, v]")
            if not (-0.5 <= drag[0] <= self.media.width - 0.5 and -0.5 <= drag[1] <= self.media.height - 0.5):
                raise ControlError(f"drag_to {drag!r}: outside the {self.media.width}x{self.media.height} image")
            drag = (float(drag[0]), float(drag[1]))
        mask = body.get("mask", False)
        if not isinstance(mask, bool):
            raise ControlError(f"mask {mask!r}: expected true or false")
        scene_from_dict(scene)  # a scene the spec refuses: 400 here, not on the render thread
        return RenderRequest(scene, frame, drag, mask)

    def render(self, req: RenderRequest, timeout: float = 120.0) -> dict:
        """Run ``req`` (newest wins: raises :class:`arshadow.preview.worker.Superseded` when dropped)."""
        t0 = time.perf_counter()
        out: dict = self.worker.submit((req, t0)).result(timeout)
        return out

    def close(self) -> None:
        self.worker.close()

    # -- the render thread --------------------------------------------------------------------------
    def _session_for(self, spec: Any) -> Any:
        """The session for ``spec``: the current one moved / relit when only the model or lights differ."""
        from ..session import Session

        cur = self._spec
        if self._session is None or spec.replace(model=cur.model, lights=cur.lights) != cur:
            if self._ctx is None:
                from ..gl.context import create_context  # the one context, made on this thread

                self._ctx = create_context()
            if self._session is not None:
                self._session.close()
            self._session = Session(spec, context=self._ctx)
        else:
            if spec.model != cur.model:
                self._session.set_model(spec.model)
            if spec.lights != cur.lights:
                self._session.set_lights(list(spec.lights))
        self._spec = spec
        return self._session

    def _pose(self, session: Any, index: int, image: np.ndarray) -> Any:
        pose = self._poses.get(index)
        if pose is None:
            pose = self._poses[index] = session.track(image)
        return pose

    def _run(self, job: tuple) -> dict:
        req, t_submit = job
        t0 = time.perf_counter()
        scene = {k: (list(v) if isinstance(v, list) else v) for k, v in req.scene.items()}
        image = self.media.frame(req.frame)
        spec = scene_from_dict(scene)
        if req.drag_to is not None and self._spec is not None:  # moved once, below, when the place is known
            spec = spec.replace(model=self._spec.model)
        session = self._session_for(spec)
        try:
            pose = self._pose(session, req.frame, image)
        except MarkerNotFoundError as exc:
            return {"image": _data_url(image), "error": str(exc), "scene": scene, "controls": controls_of(scene)}
        H, W = image.shape[:2]
        cal = session.calibration(W, H)
        cfw = session.ground_camera(pose.cam_from_world)
        if req.drag_to is not None:
            g = ground_point(cal.intrinsics, cfw, req.drag_to)
            if g is None:
                raise ControlError(f"drag_to {list(req.drag_to)}: that pixel's ray does not meet the ground")
            scene["place"] = [float(g[0]), float(g[1]), float(scene["place"][2])]
            session = self._session_for(scene_from_dict(scene))
        t1 = time.perf_counter()
        res = session.render(image, pose, name=self.media.name, want_mask=req.want_mask)
        t2 = time.perf_counter()
        png = _data_url(res.composite)
        mask = _data_url(res.mask) if req.want_mask and res.mask is not None else None
        t3 = time.perf_counter()
        with self._last_lock:
            self._last = {"scene": scene, "frame": req.frame}
        length = float(session.scene.tracker.get("marker_length") or 0.05)
        axes = cal.intrinsics.project(np.array([[0, 0, 0], [length, 0, 0], [0, length, 0], [0, 0, length]], float), cfw)
        anchor = cal.intrinsics.project(np.asarray([scene["place"]], float), cfw)[0]
        item = res.item.to_dict()
        return jsonable(
            {
                "image": png,
                "mask": mask,
                "scene": scene,
                "controls": controls_of(scene),
                "frame": req.frame,
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
        )

    def _release(self) -> None:
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
