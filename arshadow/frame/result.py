"""What a session returns for a frame: :class:`FrameResult` (composite, mask, pose, camera, report item,
timings, plan, layers), shared by :class:`arshadow.frame.session.Session` and the code that consumes its results
(video engine, notebooks, exports) without importing the engine.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import cv2
import numpy as np

from ..compose.layers import Layers
from ..plan.planner import FramePlan
from .report import ReportItem, StageTimings

if TYPE_CHECKING:
    from ..tracking.pose import MarkerPose

__all__ = ["FrameResult"]


@dataclass(repr=False)
class FrameResult:
    """One frame's result (fields are added at the end, with defaults).

    Attributes
    ----------
    composite : (H, W, 3) uint8
        The photo with the object and its shadow (BGR).
    mask : (H, W) uint8 or None
        The shadow mask of CONVENTIONS.md (None when not asked for).
    pose : arshadow.tracking.pose.MarkerPose or None
        The tracked pose (its ``cam_from_world`` is ``cam_from_marker``); None when rendering at a given
        ``cam_from_marker`` matrix or a plan.
    cam_from_world : (4, 4) float64
        The camera rendered with, in the scene's world frame, the ground's
        (:meth:`arshadow.frame.session.Session.ground_camera`; the marker's pose itself unless ``--ground`` moves
        the ground).
    item : arshadow.frame.report.ReportItem
        The report entry (``output``/``mask`` paths left for the caller).
    timings : arshadow.frame.report.StageTimings
        Milliseconds per stage.
    plan : arshadow.plan.FramePlan
        What was decided for the frame, with reasons (``plan.decisions``).
    layers : arshadow.compose.layers.Layers or None
        The object (premultiplied linear RGBA) and shadow (multiply pass) layers, when asked for
        (``layers=True``): ``plate x shadow + object`` in linear light is the composite (docs/export.md).
    """

    composite: np.ndarray
    mask: np.ndarray | None
    pose: MarkerPose | None
    cam_from_world: np.ndarray
    item: ReportItem
    timings: StageTimings = field(default_factory=StageTimings)
    plan: FramePlan | None = None
    layers: Layers | None = None

    def __repr__(self) -> str:
        """One short line (size, status, the camera's distance from the marker, timings), not the arrays."""
        h, w = np.shape(self.composite)[:2]
        cam = "no camera"
        if self.cam_from_world is not None:
            m = np.asarray(self.cam_from_world, np.float64)
            cam = f"camera {float(np.linalg.norm(m[:3, :3].T @ m[:3, 3])):.3f} m from the marker"
        t = self.timings
        return (
            f"FrameResult({w}x{h}, {getattr(self.item, 'status', '?')}, {cam}, mask={self.mask is not None}, "
            f"layers={self.layers is not None}, {t.total:.1f} ms: detect {t.detect:.1f}, pose {t.pose:.1f}, "
            f"render {t.render:.1f}, composite {t.composite:.1f})"
        )

    def _repr_png_(self) -> bytes:
        """The composite as PNG bytes: a result shows itself as an image in Jupyter."""
        ok, buf = cv2.imencode(".png", self.composite)
        return buf.tobytes() if ok else b""

    @property
    def timings_ms(self) -> dict[str, float]:
        """``timings`` as the report's ``{stage: ms}`` (rounded to microseconds)."""
        return self.timings.as_dict(3)
