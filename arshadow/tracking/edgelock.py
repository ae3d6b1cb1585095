"""A video's edge-fit space, decided once per marker: the ``edge`` refinement's space check skipped once the
video has shown it blurs in code values.

The ``edge`` corner refinement (:func:`arshadow.tracking.refine.refine_edges`, ``space="auto"``) fits each
marker's border in code values and then measures the border's width to tell whether the blur acted in
code values or in linear light: 0.15-0.45 ms a marker a frame (docs/tracking.md). How a camera blurs and
encodes is a property of the camera and its processing, not of the frame, so a video need not ask on
every frame. :class:`EdgeSpaceLock` keeps per marker id the run of frames in a row whose check found no
significant bias (the code-value fit was the answer: linear weight exactly 0); after
:data:`LOCK_FRAMES` of them the marker is *locked* to the code-value fit for the rest of the video, and its
later frames skip the check. Those frames' corners are what the check would have given whenever it would
again have found no bias, bit for bit (the same code-value fit). Any other outcome (a significant bias:
weight above 0) breaks the run; a frame whose border cannot be measured (no white cell along it, the
marker too small: weight NaN) neither counts nor breaks it. A marker blurred in linear light is never
locked and keeps its per-frame interpolation.

The lock is part of the trackers' state (:meth:`state`, compared at a chunked video's boundaries: two
runs with equal states refine the next frame alike) and is forgotten at a new video (:meth:`reset`).
Photos never use one (each photo may come from another camera).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

__all__ = ["LOCK_FRAMES", "EdgeSpaceLock"]

#: frames in a row whose space check found the code values right after which a marker's check is skipped
LOCK_FRAMES = 5


class EdgeSpaceLock:
    """Per marker id: the code-value fit decided for the rest of a video after :data:`LOCK_FRAMES` frames
    in a row said so. Shared by a video's trackers (the fast pass and the full search).

    Parameters
    ----------
    frames : int
        Frames in a row (each marker's own) that lock it.

    Examples
    --------
    >>> lock = EdgeSpaceLock(frames=2)
    >>> lock.spaces([7, 9])
    ['auto', 'auto']
    >>> lock.observe([7, 9], [0.0, 0.4]); lock.observe([7, 9], [0.0, 0.0])
    >>> lock.spaces([7, 9]), lock.state()
    (['code', 'auto'], {'edge_code': [7], 'edge_runs': {'9': 1}})
    """

    def __init__(self, frames: int = LOCK_FRAMES) -> None:
        if frames < 1:
            raise ValueError(f"frames must be at least 1, got {frames}")
        self.frames = int(frames)
        self._runs: dict[int, int] = {}
        self._code: set[int] = set()

    def reset(self) -> None:
        """A new video: every marker checked again."""
        self._runs.clear()
        self._code.clear()

    def spaces(self, ids: Sequence[int] | npt.ArrayLike) -> list[str]:
        """The ``space`` of :func:`arshadow.tracking.refine.refine_edges` for each marker of ``ids (n,)``:
        ``"code"`` for a locked marker, ``"auto"`` (checked) for the others."""
        return ["code" if int(i) in self._code else "auto" for i in np.asarray(ids).reshape(-1)]

    def observe(self, ids: Sequence[int] | npt.ArrayLike, weights: npt.ArrayLike) -> None:
        """One frame's outcome: the linear-light weights ``(n,) float64`` of the markers ``ids (n,)``
        (:attr:`arshadow.tracking.refine.EdgeRefinement.linear_weight`; a locked marker's is ignored)."""
        for i, w in zip(np.asarray(ids).reshape(-1), np.asarray(weights, np.float64).reshape(-1), strict=True):
            m = int(i)
            if m in self._code or np.isnan(w):
                continue
            if w == 0.0:
                self._runs[m] = self._runs.get(m, 0) + 1
                if self._runs[m] >= self.frames:
                    self._code.add(m)
                    del self._runs[m]
            else:
                self._runs.pop(m, None)

    def state(self) -> dict[str, object]:
        """What the next frame's refinement depends on, JSON-able: the locked ids and the runs under way."""
        return {"edge_code": sorted(self._code), "edge_runs": {str(k): v for k, v in sorted(self._runs.items())}}
