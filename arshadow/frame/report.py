"""The JSON report of CONVENTIONS.md: ``{"arshadow": VERSION, "images": [ITEM, ...]}``.

A :class:`ReportItem` is one input's (or one video frame's) entry, typed: every key the report can carry
is a field, filled once by whoever knows it (the tracker's pose, the planner and executor's frame, the
photo loop's paths, the video engine's frame time). :meth:`ReportItem.to_dict` writes the always-present
keys, then the optional ones that are set (not None), in the order of :data:`OPTIONAL_KEYS`.

:class:`StageTimings` are the per-stage milliseconds of a frame (:data:`STAGES`).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field, fields
from typing import TYPE_CHECKING, Any

import numpy as np

from .. import __version__
from ..scene.sanity import pose_flag_reasons
from ..transforms import rvec_tvec_from_matrix

if TYPE_CHECKING:
    from ..tracking.pose import MarkerPose

__all__ = ["ReportItem", "StageTimings", "STAGES", "OPTIONAL_KEYS", "make_report", "jsonable"]

#: the per-stage timings of a frame (report ``timings_ms``)
STAGES = ("detect", "pose", "silhouette", "volume", "render", "readback", "warp", "composite", "total")


@dataclass
class StageTimings:
    """Milliseconds spent per stage of one frame (:data:`STAGES`); stages add to their field.

    >>> t = StageTimings(detect=1.25, render=2.0)
    >>> t.render += 0.5
    >>> t.as_dict()["render"], t.sum()
    (2.5, 3.75)
    """

    detect: float = 0.0
    pose: float = 0.0
    silhouette: float = 0.0
    volume: float = 0.0
    render: float = 0.0
    readback: float = 0.0
    warp: float = 0.0
    composite: float = 0.0
    total: float = 0.0

    def add(self, other: StageTimings) -> None:
        """Add another frame's stage times (not ``total``) to these."""
        for k in STAGES[:-1]:
            setattr(self, k, getattr(self, k) + getattr(other, k))

    def sum(self) -> float:
        """The sum of the stages (without ``total``)."""
        return float(sum(getattr(self, k) for k in STAGES[:-1]))

    def as_dict(self, digits: int | None = None) -> dict[str, float]:
        """``{stage: ms}`` in :data:`STAGES` order (rounded to ``digits`` when given: the report's 3)."""
        if digits is None:
            return {k: float(getattr(self, k)) for k in STAGES}
        return {k: round(float(getattr(self, k)), digits) for k in STAGES}


#: the optional keys of an item, in the order the report writes them (only those set)
OPTIONAL_KEYS = (
    "calibration_scaled",
    "notes",
    "detector",
    "frame",
    "time_s",
    "sun",
    "pose_flagged",
    "flag_reasons",
    "reference_id",
    "pose_notes",
    "opencv_board_rvec",
    "opencv_board_tvec",
    "n_points",
    "kind",
    "raw",
    "pose_choice",
    "modes",
    "roi",
    "canvas",
    "znear",
    "plan",
    "content",
    "composited",
    "compose",
    "title",
    "layers",
    "ground",
    "exposure",
)


@dataclass
class ReportItem:
    """One input's entry; field names are the report's keys (CONVENTIONS.md).

    Always written: ``input`` ... ``timings_ms``. Optional (written when not None, :data:`OPTIONAL_KEYS`):

    - tracking: ``calibration_scaled`` (``{"from": [w, h], "to": [w, h]}``; ``arshadow pose``: a bool),
      ``detector`` (set when the fast pass found nothing and the full search ran), ``pose_flagged`` and
      ``flag_reasons`` (why, one text per reason), ``reference_id`` (single marker: the marker whose frame
      the pose is in; a video's held frame: the last tracked one's), ``pose_notes`` (reasons measured to
      be wrong more often than right for the tracker's refinement: reported, not flagged; docs/tracking.md),
      ``opencv_board_rvec``/``opencv_board_tvec`` (boards), ``n_points``, ``kind`` (``arshadow pose``);
    - the frame: ``modes`` (per light), ``roi``, ``canvas`` (``[x0, y0, w, h]``), ``znear``, ``plan`` (the
      planner's decisions with their reasons, docs/planner.md), ``content`` (canvas pixels with content),
      ``composited`` (photo pixels composited), ``compose`` (``cpu`` | ``gpu``), ``notes``;
    - video frames: ``frame``, ``time_s``, ``sun``, ``raw`` (the tracked pose before smoothing),
      ``pose_choice``;
    - ``title`` (the demo's caption);
    - ``layers`` (``{layer name: file}``: the compositing layers written, docs/export.md);
    - ``ground``: the ground spec (``--ground``) when it is not the marker plane; ``rvec``/``tvec`` stay
      the marker's pose.
    - ``exposure``: the marker paper's measurement and the gain on the object's colour
      (:meth:`arshadow.estimate.match.ExposureMatch.gain`; absent with ``--no-exposure``).
    """

    input: str
    output: str | None = None
    mask: str | None = None
    status: str = "ok"  # ok | no_marker | error
    error: str | None = None
    marker_ids: list[int] = field(default_factory=list)
    rvec: list[float] | None = None
    tvec: list[float] | None = None
    reprojection_error_px: float | None = None
    pose_ambiguity: float | None = None
    mode: str | None = None  # zpass | zfail | planar
    silhouette_edges: int | None = None
    timings_ms: dict[str, float] = field(default_factory=dict)
    # -- optional keys (OPTIONAL_KEYS)
    calibration_scaled: dict | bool | None = None
    notes: list[str] | None = None
    detector: str | None = None
    frame: int | None = None
    time_s: float | None = None
    sun: list | None = None
    pose_flagged: bool | None = None
    flag_reasons: list[str] | None = None
    reference_id: int | None = None
    pose_notes: list[str] | None = None
    opencv_board_rvec: list[float] | None = None
    opencv_board_tvec: list[float] | None = None
    n_points: int | None = None
    kind: str | None = None
    raw: dict | None = None
    pose_choice: str | None = None
    modes: list[str] | None = None
    roi: list[int] | None = None
    canvas: list[int] | None = None
    znear: float | None = None
    plan: dict | None = None
    content: list[int] | None = None
    composited: list[int] | None = None
    compose: str | None = None
    title: str | None = None
    layers: dict | None = None
    ground: str | None = None
    exposure: dict | None = None

    def set_pose(self, pose: MarkerPose) -> None:
        """Fill the pose keys from an :class:`arshadow.tracking.pose.MarkerPose`.

        ``rvec``/``tvec`` are world -> camera in arshadow's world frame (z up). For a board that frame is
        OpenCV's board frame turned 180 degrees about x (docs/tracking.md), so the item also carries
        OpenCV's own board pose as ``opencv_board_rvec``/``opencv_board_tvec``
        (``cam_from_opencv_board = cam_from_world @ diag(1, -1, -1, 1)``).
        """
        self.marker_ids = [int(i) for i in pose.marker_ids]
        if getattr(pose, "kind", "marker") == "marker" and self.marker_ids:
            self.reference_id = self.marker_ids[0]
        self.rvec = np.asarray(pose.rvec, float).ravel().tolist()
        self.tvec = np.asarray(pose.tvec, float).ravel().tolist()
        self.reprojection_error_px = float(pose.reprojection_error_px)
        self.pose_ambiguity = None if pose.pose_ambiguity is None else float(pose.pose_ambiguity)
        # the ratio is at or above the tracker's threshold: the mirrored solution may be the true one
        self.pose_flagged = bool(getattr(pose, "flagged", getattr(pose, "ambiguous", False)))
        self.flag_reasons = pose_flag_reasons(
            pose, self.pose_flagged
        )  # why it is flagged ([] when it is not; arshadow.scene.sanity)
        self.pose_notes = [str(r) for r in getattr(pose, "notes", None) or []] or None
        if getattr(pose, "kind", None) in ("gridboard", "charuco"):
            # deferred: the report module loads without OpenCV (arshadow pose / render only ever get here)
            from ..tracking.board import OPENCV_BOARD_TO_WORLD

            world_from_board = np.eye(4)
            world_from_board[:3, :3] = OPENCV_BOARD_TO_WORLD
            m = np.asarray(pose.cam_from_world, float) @ world_from_board
            r, t = rvec_tvec_from_matrix(m)
            self.opencv_board_rvec, self.opencv_board_tvec = r.tolist(), t.tolist()

    def to_dict(self) -> dict[str, Any]:
        """The report's JSON object: the fixed keys, then the optional keys that are set."""
        d = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name in _OPTIONAL and v is None:
                continue
            d[f.name] = v
        out: dict[str, Any] = jsonable(d)
        return out


_OPTIONAL = frozenset(OPTIONAL_KEYS)


def make_report(items: Iterable[ReportItem | dict[str, Any]]) -> dict[str, Any]:
    """Wrap report items (``ReportItem`` or dicts) into the top-level report dict."""
    return {
        "arshadow": __version__,
        "images": [i.to_dict() if isinstance(i, ReportItem) else jsonable(i) for i in items],
    }


def jsonable(x: Any) -> Any:
    """numpy scalars/arrays -> Python; non-finite floats -> None (JSON has no NaN)."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist())
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, float) and not np.isfinite(x):
        return None
    return x
