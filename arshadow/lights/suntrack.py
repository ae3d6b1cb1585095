"""The sun over a sequence of instants (a video or a time-lapse): :class:`SunTrack`, with the lazy
silhouette recomputation that a slowly moving sun allows, and :func:`frame_times`. The sun's position
for one instant is :mod:`arshadow.lights.sun`."""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from datetime import datetime, timedelta
from typing import Any

import numpy as np

from ..errors import LightError
from .sun import SunPosition, angle_between_deg, as_utc, check_place, sun_light_direction, sun_positions

__all__ = ["SunTrack", "TrackFrame", "frame_times"]


@dataclass(frozen=True, eq=False)
class TrackFrame:
    """One frame of a :class:`SunTrack`.

    Attributes
    ----------
    when : datetime
    position : SunPosition
    world : (3,) float64
        The true sun direction at this frame (world frame).
    world_used : (3,) float64
        The direction the renderer should use: the one of the last recompute (its silhouette is valid for
        it). Differs from ``world`` by ``stale_deg`` <= the track's ``recompute_deg``.
    above_horizon : bool
    recompute : bool
        True when the silhouette must be recomputed at this frame (first frame, direction moved more than
        ``recompute_deg`` since the last recompute, or the sun crossed the horizon).
    stale_deg : float
        Angle between ``world`` and ``world_used``.
    """

    when: datetime
    position: SunPosition
    world: np.ndarray
    world_used: np.ndarray
    above_horizon: bool
    recompute: bool
    stale_deg: float


class SunTrack:
    """The sun over a sequence of instants (a video or time-lapse), with lazy silhouette recomputation.

    The silhouette of a static occluder depends only on the light direction. The sun moves at most
    0.25 deg per minute (15 deg/h at the equator, less elsewhere), so for a video the silhouette is
    recomputed only when the direction has moved more than ``recompute_deg`` since the last recompute; in
    between, the renderer keeps the last recompute's direction (``world_used``), so the shadow is at most
    ``recompute_deg`` off (the cost of the saving, reported per frame as ``stale_deg``).

    Parameters
    ----------
    lat, lon, elevation : float
    north_deg : float
        Compass bearing of the world +y axis.
    recompute_deg : float
        Threshold angle, degrees (>= 0; 0 recomputes on every change).
    model, refraction, **kwargs
        As :func:`sun_position` / :func:`sun_light_direction`.

    Examples
    --------
    >>> from datetime import datetime, timedelta, timezone
    >>> t0 = datetime(2011, 4, 22, 10, 59, tzinfo=timezone(timedelta(hours=8)))
    >>> frames = SunTrack(1.28, 103.45, recompute_deg=0.5).track([t0 + timedelta(seconds=10 * i) for i in range(30)])
    >>> [f.recompute for f in frames].count(True)   # 5 minutes of sun: ~1.2 deg of motion
    3
    """

    def __init__(
        self,
        lat: float,
        lon: float,
        elevation: float = 0.0,
        north_deg: float = 0.0,
        recompute_deg: float = 0.1,
        model: str = "spa",
        refraction: bool = False,
        **kwargs: Any,
    ) -> None:
        self.lat, self.lon, self.elevation = check_place(lat, lon, elevation)
        self.north_deg = float(north_deg)
        if not math.isfinite(self.north_deg):
            raise LightError(f"north bearing {north_deg!r} is not finite")
        self.recompute_deg = float(recompute_deg)
        if not (math.isfinite(self.recompute_deg) and self.recompute_deg >= 0.0):
            raise LightError(f"recompute angle must be >= 0 degrees, got {recompute_deg!r}")
        self.model, self.refraction, self.kwargs = model, bool(refraction), kwargs
        self._last: tuple[np.ndarray, bool] | None = None  # (world_used, above_horizon) of the last recompute

    def reset(self) -> None:
        """Forget the last recompute (the next frame recomputes)."""
        self._last = None

    def state(self) -> tuple[list[float], bool] | None:
        """The history the next frame depends on (the last recompute's direction and horizon side), as
        plain picklable values: ``None`` or ``((3,) list of float, bool)``. :meth:`restore` it to resume a
        video (or start a chunk of it) exactly where the recompute schedule was."""
        if self._last is None:
            return None
        return ([float(v) for v in self._last[0]], bool(self._last[1]))

    def restore(self, state: tuple[Sequence[float], bool] | None) -> None:
        """Set the history saved by :meth:`state` (None: as :meth:`reset`)."""
        if state is None:
            self._last = None
            return
        world = np.array(state[0], dtype=np.float64).reshape(3)
        world.setflags(write=False)
        self._last = (world, bool(state[1]))

    def track(self, times: Iterable[datetime]) -> list[TrackFrame]:
        """Sun direction for each instant in ``times`` (aware datetimes, in frame order)."""
        positions = sun_positions(times, self.lat, self.lon, self.elevation, self.model, **self.kwargs)
        out = []
        for w, p in zip(times, positions, strict=True):
            world, above = sun_light_direction(p, self.north_deg, self.refraction)
            world.setflags(write=False)
            if self._last is None or above != self._last[1]:
                recompute = True
            else:
                recompute = float(angle_between_deg(world, self._last[0])) > self.recompute_deg
            if recompute:
                self._last = (world, above)
            assert self._last is not None  # set above when it was None
            used = self._last[0]
            out.append(TrackFrame(w, p, world, used, above, recompute, float(angle_between_deg(world, used))))
        return out

    def update(self, when: datetime) -> TrackFrame:
        """One frame (streaming use)."""
        return self.track([when])[0]


def frame_times(start: datetime, fps: float, n: int, speed: float = 1.0) -> list[datetime]:
    """Instants of ``n`` video frames from ``start`` at ``fps``, sped up ``speed`` times (time-lapse:
    ``speed = 600`` makes one video second ten minutes of sun motion)."""
    start = as_utc(start).astimezone(start.tzinfo)
    if not (fps > 0 and speed > 0):
        raise LightError(f"fps and speed must be > 0 (got {fps!r}, {speed!r})")
    return [start + timedelta(seconds=i * speed / fps) for i in range(int(n))]
