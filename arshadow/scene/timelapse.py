"""The time-lapse of a scene (``arshadow video --time-lapse START[,SPEED]``, the ``time_lapse`` key of a scene
file): sun lights that follow a video's frame times. Part of :class:`arshadow.scene.SceneSpec`."""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from datetime import datetime

from ..errors import LightError, UsageError
from ..lights.spec import Light, SunLightTrack, parse_light, parse_sun_track, parse_time

__all__ = ["TimeLapse", "parse_time_lapse", "time_lapse_spec"]


@dataclass(frozen=True)
class TimeLapse:
    """Sun lights that follow a video's frame times (``arshadow video --time-lapse START[,SPEED]``).

    Attributes
    ----------
    start : str
        ISO time with a UTC offset: the scene's time at the video's first frame.
    speed : float
        Scene seconds per video second (> 0).
    recompute_deg : float
        A sun's silhouette is recomputed only when it moved more than this since the last recompute.
    """

    start: str
    speed: float = 1.0
    recompute_deg: float = 0.1

    def lights(self, specs: Iterable[str | Light]) -> tuple[list[Light], list[SunLightTrack], list[Light]]:
        """``(static lights, sun tracks, first lights)`` of light specs: each ``sun:`` spec becomes a
        :class:`arshadow.lights.spec.SunLightTrack`; the first lights are the static ones plus the suns at
        ``start``. UsageError without a sun."""
        static: list[Light] = []
        tracks: list[SunLightTrack] = []
        for s in specs:
            if isinstance(s, str) and s.strip().lower().startswith("sun:"):
                tracks.append(parse_sun_track(s, recompute_deg=self.recompute_deg))
            else:
                static.append(parse_light(s) if isinstance(s, str) else s)
        if not tracks:
            raise UsageError("--time-lapse needs a sun light (--light sun:LAT,LON[,TIME][,NORTH])")
        start = self.when()[0]
        first = list(static)
        for tr in tracks:
            tr.reset()
            first.append(tr.light(tr.update(start)))
            tr.reset()
        return static, tracks, first

    def when(self) -> tuple[datetime, float]:
        """``(start datetime, speed)``."""
        return parse_time_lapse(f"{self.start},{self.speed!r}")


def parse_time_lapse(text: str) -> tuple[datetime, float]:
    """``START[,SPEED]`` -> (aware datetime, speed > 0). UsageError on bad input.

    Examples
    --------
    >>> parse_time_lapse("2024-06-21T06:00+02:00,600")[1]
    600.0
    """
    start_text, sep, speed_text = str(text).rpartition(",")
    if not sep:
        start_text, speed_text = text, "1"
    try:
        speed = float(speed_text)
    except ValueError:
        raise UsageError(f"--time-lapse {text!r}: SPEED {speed_text!r} is not a number") from None
    if not (math.isfinite(speed) and speed > 0):
        raise UsageError(f"--time-lapse {text!r}: SPEED must be a positive number")
    try:
        start = parse_time(start_text.strip(), what="--time-lapse START")
    except LightError as exc:
        raise UsageError(str(exc)) from None
    return start, speed


def time_lapse_spec(text: str | None, recompute_deg: float, lights: Iterable[str | Light]) -> TimeLapse | None:
    """The :class:`TimeLapse` of a scene's ``time_lapse`` (``START[,SPEED]`` or None) and ``recompute_deg``
    keys, checked (UsageError: a bad START or SPEED, a negative angle, no sun among the light specs)."""
    deg = float(recompute_deg)
    if not (math.isfinite(deg) and deg >= 0):
        raise UsageError(f"--recompute-deg {recompute_deg}: must be >= 0 degrees")
    if text is None:
        return None
    start, speed = parse_time_lapse(str(text))
    if not any(isinstance(s, str) and s.strip().lower().startswith("sun:") for s in lights):
        raise UsageError("--time-lapse needs a sun light (--light sun:LAT,LON[,TIME][,NORTH])")
    return TimeLapse(start.isoformat(), speed, deg)
