"""Draft frames while a drag or a turn is under way: the same renderer, the object left where it was.

Moving the object makes a new mesh, and a new mesh costs its adjacency, convexity and GL buffers anew
(~100 ms for the 8 536-face knot at 720p here) before its ~12 ms render. While the pointer moves, the
preview renders an *equivalent* scene instead: the object stays where the drag started, and the camera and
the lights move the other way. Sliding the object on the ground and turning it about the vertical axis are
rigid motions ``A`` of the ground frame that keep the ground plane (z = 0) in place, so the scene "object
moved by A" is, pixel for pixel up to rounding, "camera ``cam_from_world @ A``, lights ``A^-1 L``, object
unmoved". The release renders the moved scene exactly (what ``render`` writes).

One thing is not equivalent: the marker paper the exposure match reads is where the moved camera says it
is, so drafts keep the exposure gain measured at the drag's start (the draft session smooths the exposure
as a video does and is told the marker is not seen).

Examples
--------
>>> from arshadow.scene import ModelSpec
>>> a = ModelSpec("box:1,1,1", place=(0.1, 0.0, 0.0), rotate=(0.0, 0.0, 0.0))
>>> b = ModelSpec("box:1,1,1", place=(0.1, 0.2, 0.0), rotate=(0.0, 0.0, 90.0))
>>> ground_motion(a, b).round(6).tolist()
[[0.0, -1.0, 0.0, 0.1], [1.0, 0.0, 0.0, 0.1], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
>>> ground_motion(a, ModelSpec("box:1,1,1", place=(0.1, 0.0, 0.01))) is None  # raised: not a ground motion
True
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..transforms import invert_rigid

__all__ = ["ground_motion", "moved_lights", "draft_pose"]


def ground_motion(before: Any, after: Any) -> np.ndarray | None:
    """The rigid motion ``A (4, 4) float64`` (ground frame) taking model ``before`` onto ``after``
    (:class:`arshadow.scene.ModelSpec`), when they differ only by their place's x, y and the turn about z;
    else None.

    ``after``'s vertices are ``A @ before``'s: the model's rotation is ``Rz @ Ry @ Rx`` (fixed axes), so a
    change of ``rz`` by ``d`` turns the placed mesh by ``Rz(d)`` about the vertical through its place.
    """
    same = dataclasses.replace(after, place=before.place, rotate=(*after.rotate[:2], before.rotate[2]))
    if same != before or float(after.place[2]) != float(before.place[2]):
        return None
    d = math.radians(float(after.rotate[2]) - float(before.rotate[2]))
    c, s = math.cos(d), math.sin(d)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    p0, p1 = np.asarray(before.place, np.float64), np.asarray(after.place, np.float64)
    a = np.eye(4)
    a[:3, :3] = rot
    a[:3, 3] = p1 - rot @ p0
    return a


def moved_lights(lights: Sequence[Any], motion: np.ndarray) -> list[Any]:
    """The lights (:class:`arshadow.lights.spec.Light`) moved by ``motion (4, 4)``: point lights' positions
    and directional lights' directions (their weights, sizes and labels kept)."""
    rot, t = motion[:3, :3], motion[:3, 3]
    out = []
    for lt in lights:
        v = np.asarray(lt.vector, np.float64)
        v = rot @ v + t if lt.kind == "point" else rot @ v
        out.append(dataclasses.replace(lt, vector=v))
    return out


def draft_pose(cam_from_ground: np.ndarray, motion: np.ndarray, marker_from_ground: Any = None) -> np.ndarray:
    """``cam_from_marker (4, 4)`` to render the unmoved object at: the session's plan then uses
    ``cam_from_ground @ motion`` (``marker_from_ground`` None: the ground is the marker plane)."""
    cfg = np.asarray(cam_from_ground, np.float64) @ motion
    out: np.ndarray = (
        cfg if marker_from_ground is None else cfg @ invert_rigid(np.asarray(marker_from_ground, np.float64))
    )
    return out
