"""The reference marker of a video: chosen once, kept, switched only when it is lost for good (the trust fixes).

A sheet of several markers and no ``--marker-id``: a photo takes the lowest id it finds, but in a video
that id changes whenever a marker comes and goes (on the shared six-marker clip: 1001 in 77 frames, 101
in 46, 601 in 8 and a false id 0 once), and each change moves the world (the marker's centre) and with it
the object. :class:`ReferenceLock` keeps one reference through a video:

- the first frame with markers chooses it: the **largest** marker found (its shortest side in pixels; ties:
  the lowest id). The largest marker gives the best pose, and a false detection is a small quad;
- a frame without the reference has no pose (it is held, then lost, like a frame without a marker), even
  when other markers are found;
- after :data:`REFERENCE_SWITCH_FRAMES` searches in a row that find other markers but not the reference
  (a frame's search and, on a miss, the colour frame's retry, :func:`arshadow.tracking.detect.retry_due`:
  between half that many frames and that many), the reference is lost for good: the largest marker found
  becomes the new one. The video layer says so, naming the frames (:class:`ReferenceTally`).

:class:`ReferenceTally` reads the frames' reference ids (the per-frame records' ``reference_id``) and
writes the warning line.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import numpy.typing as npt

from ..errors import MarkerNotFoundError

__all__ = ["REFERENCE_SWITCH_FRAMES", "ReferenceLock", "ReferenceTally", "largest_marker"]

#: searches in a row with other markers but not the reference after which the reference is lost for good
#: (the video's default hold is 12 frames: a reference hidden for less is held over, not replaced)
REFERENCE_SWITCH_FRAMES = 25


def largest_marker(by_id: Mapping[int, npt.ArrayLike]) -> int:
    """The id whose quad ``(4, 2)`` has the longest shortest side (ties: the lowest id).

    >>> largest_marker({3: [[0, 0], [10, 0], [10, 10], [0, 10]], 7: [[0, 0], [30, 0], [30, 30], [0, 30]]})
    7
    """

    def side(corners: npt.ArrayLike) -> float:
        q = np.asarray(corners, np.float64).reshape(-1, 2)[:4]
        return float(np.linalg.norm(q - np.roll(q, 1, axis=0), axis=1).min())

    best: int = min(by_id, key=lambda i: (-side(by_id[i]), int(i)))
    return best


class ReferenceLock:
    """One video's reference marker, shared by the trackers that search it (the fast pass and the full
    search).

    Parameters
    ----------
    switch_after : int
        Searches in a row with other markers but not the reference after which it is replaced.

    Attributes
    ----------
    id : int or None
        The reference (None before the first frame with a marker).
    missing : int
        Searches in a row (by the tracker that has the last word) with other markers but not the
        reference.

    Examples
    --------
    >>> lock = ReferenceLock(switch_after=2)
    >>> sq = lambda s: [[0, 0], [s, 0], [s, s], [0, s]]
    >>> lock.choose({5: sq(40), 2: sq(20)}), lock.choose({2: sq(20), 5: sq(41)})
    (5, 5)
    >>> lock.choose({2: sq(20)})
    Traceback (most recent call last):
    ...
    arshadow.errors.MarkerNotFoundError: reference marker 5 not found (found 2)
    >>> lock.choose({2: sq(20)})
    2
    """

    def __init__(self, switch_after: int = REFERENCE_SWITCH_FRAMES):
        self.switch_after = int(switch_after)
        self.id: int | None = None
        self.missing = 0

    def reset(self) -> None:
        """A new video: the next frame with markers chooses again."""
        self.id, self.missing = None, 0

    def choose(self, by_id: Mapping[int, npt.ArrayLike], count: bool = True) -> int:
        """The reference id for a frame whose markers are ``by_id`` (id -> (4, 2) corners, not empty).

        ``count``: this call has the last word on the frame (the full search; the fast pass, whose miss
        is followed by the full search, passes False). Raises :class:`MarkerNotFoundError` when the
        reference is not among them and is not (yet) lost for good.
        """
        if self.id is None:
            self.id = largest_marker(by_id)
        if self.id in by_id:
            self.missing = 0
            return self.id
        if count:
            self.missing += 1
            if self.missing >= self.switch_after:
                self.id, self.missing = largest_marker(by_id), 0
                return self.id
        found = ", ".join(map(str, sorted(by_id)))
        raise MarkerNotFoundError(f"reference marker {self.id} not found (found {found})")

    def state(self) -> dict[str, int | None]:
        """What the next frame's choice depends on, JSON-able (compared across a video's chunks)."""
        return {"reference": self.id, "reference_missing": self.missing}


class ReferenceTally:
    """The reference ids of a video's frames, in frame order, for one warning line when it changed.

    >>> t = ReferenceTally()
    >>> for f, ref in enumerate([4, 4, None, 4, 9, 9]):
    ...     t.add(f, ref)
    >>> print(t.summary())
    the reference marker changed once: 4 -> 9 at frame 4 (4 last seen in frame 3); the object's position is relative to the reference, so it jumps there: give --marker-id to keep one marker
    """

    def __init__(self) -> None:
        self.last: tuple[int, int] | None = None  # (frame, id) of the last frame with a reference
        self.changes: list[tuple[int, int, int, int]] = []  # (frame, old id, new id, old id's last frame)

    def add(self, frame: int, reference_id: int | None) -> None:
        """A tracked frame's reference id (None: no pose, or a board)."""
        if reference_id is None:
            return
        ref = int(reference_id)
        if self.last is not None and self.last[1] != ref:
            self.changes.append((int(frame), self.last[1], ref, self.last[0]))
        self.last = (int(frame), ref)

    def summary(self) -> str | None:
        """One line, or None when the reference never changed."""
        if not self.changes:
            return None
        n = len(self.changes)
        each = "; ".join(f"{a} -> {b} at frame {f} ({a} last seen in frame {s})" for f, a, b, s in self.changes)
        times = "once" if n == 1 else f"{n} times"
        return (
            f"the reference marker changed {times}: {each}; the object's position is relative to the "
            "reference, so it jumps there: give --marker-id to keep one marker"
        )
