"""Exposure and white balance on the render path: the object shaded like the photographed marker paper.

Every photo (and every video frame, smoothed by :class:`arshadow.estimate.exposure.ExposureSmoother`) the
lit paper's linear RGB ``P`` is measured on the detected marker (:func:`measure_exposure`). The renderer
shades a horizontal face of albedo 1 as ``S = ambient + sum_i w_i max(0, n . l_i)`` (``n`` the paper's
normal, ``l_i`` the unit vector from the paper towards light ``i``, ``w_i`` its weight share); the object's
rendered linear colour is multiplied per channel by ``gain = P / S``. So an object of the paper's colour
(``--color 255,255,255``) lit like the paper records exactly ``P``: it looks like the paper in the photo,
whatever the camera's exposure and white balance. ``--no-exposure`` switches this off.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..camera.model import Intrinsics
from ..tracking.dictionary import DEFAULT_DICTIONARY
from ..transforms import invert_rigid
from .exposure import Exposure, ExposureError, ExposureSmoother, measure_exposure, paper_region

__all__ = ["ExposureMatch", "paper_shading"]


def marker_id_of(pose: Any) -> int | None:
    """The reference marker's id of a tracked pose (its first ``marker_ids``), or None."""
    ids: Any = getattr(pose, "marker_ids", ()) if pose is not None else ()
    return ids[0] if len(ids) else None


def paper_shading(lights_h: Any, weights: Any, ambient: float, paper_from_world: Any = None) -> float:
    """The renderer's shading ``S`` of the marker paper (albedo 1, no specular).

    Parameters
    ----------
    lights_h : (n, 4) float
        Homogeneous lights in the world frame (w = 0: directional, towards the light).
    weights : (n,) float
        Their weight shares.
    ambient : float
    paper_from_world : (4, 4) float64, optional
        The marker's frame from the world (ground) frame; None: the world is the marker frame.

    Examples
    --------
    >>> round(paper_shading([(0.0, 1.0, 1.0, 0.0)], [1.0], 0.25), 4)  # 45 degrees: 0.25 + 0.7071
    0.9571
    """
    M = np.eye(4) if paper_from_world is None else np.linalg.inv(np.asarray(paper_from_world, np.float64))
    n, o = M[:3, 2], M[:3, 3]  # the paper's normal and centre in the world frame
    s = float(ambient)
    for lh, w in zip(np.asarray(lights_h, np.float64).reshape(-1, 4), np.ravel(weights), strict=True):
        d = lh[:3] if abs(lh[3]) < 1e-12 else lh[:3] / lh[3] - o
        s += float(w) * max(0.0, float(n @ d) / max(float(np.linalg.norm(d)), 1e-12))
    return s


class ExposureMatch:
    """Per-frame exposure match of a session.

    Parameters
    ----------
    marker_length : float
    dictionary, marker_id
        The tracked marker (``marker_id`` None: the detected one).
    smooth : bool
        Video: smooth over frames, following auto-exposure changes (:class:`ExposureSmoother`).
    """

    def __init__(self, marker_length: float, dictionary: Any, marker_id: int | None = None, smooth: bool = False):
        self.marker_length = float(marker_length)
        self.dictionary = DEFAULT_DICTIONARY if dictionary is None else dictionary
        self.marker_id = marker_id
        self.smoother = ExposureSmoother() if smooth else None

    def gain(
        self,
        image: np.ndarray,
        intr: Intrinsics,
        cam_from_marker: np.ndarray,
        marker_id: int | None,
        geometry: Any,
        paper_from_world: Any = None,
        seen: bool = True,
    ) -> tuple[np.ndarray | None, dict]:
        """``(gain (3,) float or None, report dict)`` for one frame.

        The report dict (the report item's ``exposure``): ``paper_rgb``, ``ink_rgb``, ``white_cells``,
        ``saturated`` of the frame's measurement, ``smoothed_paper_rgb`` (video), ``shading`` (``S``) and
        ``gain``; or ``error`` when the paper cannot be measured (the object is then not changed, or keeps
        the video's last gain). ``seen`` False: the marker is not in this frame (a video frame rendered
        with a held pose): nothing is measured (the paper is not where the pose says), the video's last
        gain is kept and the dict says ``held``.
        """
        mid = marker_id if marker_id is not None else (self.marker_id if self.marker_id is not None else 0)
        rep: dict = {}
        m: Exposure | None = None
        if not seen:
            rep["held"] = True
        else:
            try:
                m = measure_exposure(image, intr, cam_from_marker, self.marker_length, self.dictionary, int(mid))
                rep.update(m.to_dict())
            except ExposureError as exc:
                rep["error"] = str(exc)
        use = m if self.smoother is None else self.smoother.update(m)
        if self.smoother is not None and use is not None:
            rep["smoothed_paper_rgb"] = [round(float(v), 6) for v in use.paper_rgb]
        lights = [ls for ls in geometry.lights]
        if use is None or not lights:
            return None, rep
        s = paper_shading(
            [ls.light_h for ls in lights], [ls.weight for ls in lights], geometry.options.ambient, paper_from_world
        )
        g = np.asarray(use.paper_rgb, np.float64) / max(s, 1e-6)
        rep["shading"] = round(s, 6)
        rep["gain"] = [round(float(v), 6) for v in g]
        return g, rep

    def frame_gain(
        self,
        image: np.ndarray,
        intr: Intrinsics,
        cam_from_ground: np.ndarray,
        pose: Any,
        geometry: Any,
        marker_from_ground: Any = None,
        prior_gain: Any = None,
        seen: bool = True,
    ) -> tuple[np.ndarray | None, dict]:
        """:meth:`gain` for a rendered frame: ``cam_from_ground (4, 4)`` the plan's camera (the ground frame,
        ``marker_from_ground`` None: the marker's), the marker id from the tracked ``pose`` (or None);
        ``prior_gain (3,)``: a gain already folded into the object's colour (``--light-from``), divided
        out; ``seen``: as :meth:`gain`."""
        mfg = marker_from_ground
        cfm = cam_from_ground if mfg is None else cam_from_ground @ invert_rigid(mfg)
        gain, rep = self.gain(image, intr, cfm, marker_id_of(pose), geometry, mfg, seen)
        if gain is not None and prior_gain is not None:
            gain = gain / np.asarray(prior_gain, np.float64)
        return gain, rep

    def region(self, intr: Intrinsics, cam_from_marker: np.ndarray, marker_id: int | None) -> tuple | None:
        """The pixels :meth:`gain` reads for this pose (:func:`arshadow.estimate.exposure.paper_region`)."""
        mid = marker_id if marker_id is not None else (self.marker_id if self.marker_id is not None else 0)
        return paper_region(intr, cam_from_marker, self.marker_length, self.dictionary, int(mid))

    def missing(self) -> None:
        """A video frame without the marker, not rendered: counts toward the smoothing's restart
        (:class:`arshadow.estimate.exposure.ExposureSmoother`)."""
        if self.smoother is not None:
            self.smoother.missing()

    def reset(self) -> None:
        """A new video: the smoothing forgets the previous frames."""
        if self.smoother is not None:
            self.smoother = ExposureSmoother()

    def state(self) -> dict | None:
        return None if self.smoother is None else self.smoother.state()

    def restore(self, st: dict | None) -> None:
        if self.smoother is not None and st is not None:
            self.smoother.restore(st)
