"""What a :class:`arshadow.frame.session.Session` carries from one frame to the next: :class:`History`.

A session renders each frame from the frame's own pose, but three things carry over between the frames of
a video (or a time-lapse of photos), and this mixin holds the user's side of them, apart from the frame path
of :mod:`arshadow.frame.session` (track, plan, render):

- the lights over time: :meth:`History.set_lights`, and the sun tracks that :meth:`History.set_time`
  moves (a time-lapse, :mod:`arshadow.lights.suntrack`);
- the exposure match's smoothing over frames (:class:`arshadow.estimate.match.ExposureMatch`, fed by the
  video engine through ``session.hooks``: :meth:`arshadow.frame.hooks.EngineHooks.observe_exposure`,
  :meth:`~arshadow.frame.hooks.EngineHooks.exposure_gap`);
- their saved state: :meth:`History.state` / :meth:`History.restore` (resume a run, or start a chunk of
  a video with the same history; the trackers' memory is compared instead:
  :meth:`arshadow.frame.hooks.EngineHooks.tracker_state`).

The mixin uses only the session's public attributes (``geometry``, ``hooks``, ``scene``).
"""

from __future__ import annotations

from collections.abc import Sequence
from datetime import datetime
from typing import TYPE_CHECKING, Any

from ..errors import UsageError
from ..lights.spec import Light, parse_light

if TYPE_CHECKING:
    from ..lights.suntrack import TrackFrame
    from ..plan.planner import SceneGeometry
    from ..scene.spec import Scene
    from .hooks import EngineHooks

__all__ = ["History"]


class History:
    """The frame-to-frame memory of a :class:`arshadow.frame.session.Session` (see the module)."""

    #: ``(static lights, sun tracks)`` that :meth:`set_time` moves, or None
    _sun: tuple[list[Light], list[Any]] | None = None

    if TYPE_CHECKING:  # provided by arshadow.frame.session.Session
        geometry: SceneGeometry
        hooks: EngineHooks
        scene: Scene

    # -- lights over time -----------------------------------------------------------------------------
    def set_lights(self, lights: Sequence[Light | str]) -> int:
        """Replace the lights (spec strings or :class:`arshadow.lights.spec.Light`), keeping the cached geometry
        of the lights that stay (:meth:`arshadow.plan.SceneGeometry.set_lights`); returns the number of
        (sample) lights to recompute."""
        return self.geometry.set_lights([parse_light(s) if isinstance(s, str) else s for s in lights])

    @property
    def sun_tracks(self) -> list[Any]:
        """The sun tracks :meth:`set_time` moves (the spec's time-lapse, or :meth:`use_sun_tracks`)."""
        return [] if self._sun is None else list(self._sun[1])

    @property
    def time_lapse(self) -> tuple[datetime, float] | None:
        """``(start datetime, speed)`` of the spec's time-lapse, or None."""
        return self.scene.time_lapse

    def use_sun_tracks(self, tracks: Sequence[Any], static: Sequence[Light] = ()) -> None:
        """Let :meth:`set_time` move the sun: ``tracks`` (:func:`arshadow.lights.spec.parse_sun_track`) plus fixed
        ``static`` lights."""
        self._sun = (list(static), list(tracks))

    def set_time(self, when: datetime) -> list[TrackFrame]:
        """Move the sun tracks of :meth:`use_sun_tracks` to ``when`` (aware datetime) and set the lights.

        Returns
        -------
        list of arshadow.lights.suntrack.TrackFrame
            One per track (``recompute``, ``stale_deg``... for the report).
        """
        if self._sun is None:
            raise UsageError("set_time needs sun tracks (Session.use_sun_tracks)")
        static, tracks = self._sun
        frames = [tr.update(when) for tr in tracks]
        self.geometry.set_lights(list(static) + [tr.light(f) for tr, f in zip(tracks, frames, strict=True)])
        return frames

    # -- saved state ------------------------------------------------------------------------------------
    def state(self) -> dict[str, Any]:
        """The history later frames depend on, picklable: the current lights with their cached silhouettes
        and volumes, the sun tracks' recompute schedule and the exposure match's smoothing.
        :meth:`restore` it (here or in another process's session of the same spec) to go on exactly as
        this session would."""
        return {
            "geometry": self.geometry.state(),
            "sun_tracks": None if self._sun is None else [tr.state() for tr in self._sun[1]],
            "exposure": None if self.hooks.exposure is None else self.hooks.exposure.state(),
        }

    def restore(self, state: dict[str, Any]) -> None:
        """Set the history saved by :meth:`state`."""
        self.geometry.restore(state["geometry"])
        if self.hooks.exposure is not None:
            self.hooks.exposure.restore(state.get("exposure"))
        if state.get("sun_tracks") is not None and self._sun is not None:
            for tr, st in zip(self._sun[1], state["sun_tracks"], strict=True):
                tr.restore(st)
