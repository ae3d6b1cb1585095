"""The JSON report of CONVENTIONS.md: ``{"arshadow": VERSION, "images": [ITEM, ...]}``."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from . import __version__
from .sanity import pose_flag_reasons


@dataclass
class ReportItem:
    """One input's entry; field names are the report's keys (CONVENTIONS.md)."""

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
    extra: dict = field(default_factory=dict)

    def set_pose(self, pose) -> None:
        """Fill the pose keys from an :class:`arshadow.tracking.pose.MarkerPose`.

        ``rvec``/``tvec`` are world -> camera in arshadow's world frame (z up). For a board that frame is
        OpenCV's board frame turned 180 degrees about x (docs/tracking.md), so the item also carries
        OpenCV's own board pose as ``opencv_board_rvec``/``opencv_board_tvec``
        (``cam_from_opencv_board = cam_from_world @ diag(1, -1, -1, 1)``).
        """
        self.marker_ids = [int(i) for i in pose.marker_ids]
        self.rvec = np.asarray(pose.rvec, float).ravel().tolist()
        self.tvec = np.asarray(pose.tvec, float).ravel().tolist()
        self.reprojection_error_px = float(pose.reprojection_error_px)
        self.pose_ambiguity = None if pose.pose_ambiguity is None else float(pose.pose_ambiguity)
        # the ratio is at or above the tracker's threshold: the mirrored solution may be the true one
        self.extra["pose_flagged"] = bool(getattr(pose, "ambiguous", False))
        self.extra["flag_reasons"] = pose_flag_reasons(pose)  # why it is flagged ([] when it is not)
        if getattr(pose, "kind", None) in ("gridboard", "charuco"):
            from .tracking.board import OPENCV_BOARD_TO_WORLD
            from .transforms import rvec_tvec_from_matrix

            world_from_board = np.eye(4)
            world_from_board[:3, :3] = OPENCV_BOARD_TO_WORLD
            m = np.asarray(pose.cam_from_world, float) @ world_from_board
            r, t = rvec_tvec_from_matrix(m)
            self.extra["opencv_board_rvec"], self.extra["opencv_board_tvec"] = r.tolist(), t.tolist()

    def to_dict(self) -> dict:
        d = asdict(self)
        extra = d.pop("extra")
        d.update(extra)
        return jsonable(d)


def make_report(items) -> dict:
    """Wrap report items (``ReportItem`` or dicts) into the top-level report dict."""
    return {
        "arshadow": __version__,
        "images": [i.to_dict() if isinstance(i, ReportItem) else jsonable(i) for i in items],
    }


def jsonable(x):
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
