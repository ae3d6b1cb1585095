"""What a :class:`arshadow.session.Session` carries from one frame to the next: :class:`History`.

A session renders each frame from the frame's own pose, but three things carry over between the frames of
a video (or a time-lapse of photos), and this mixin holds them, apart from the frame path of
:mod:`arshadow.session` (track, plan, render):

- the lights over time: :meth:`History.set_lights`, and the sun tracks that :meth:`History.set_time`
  moves (a time-lapse, :mod:`arshadow.lights.suntrack`);
- the exposure match's smoothing over frames (:class:`arshadow.estimate.match.ExposureMatch`): frames
  measured without being rendered (:meth:`History.observe_exposure`, a video chunk's primer) and frames
  without the marker (:meth:`History.exposure_gap`);
- their saved state: :meth:`History.state` / :meth:`History.restore` (resume a run, or start a chunk of
  a video with the same history; the trackers' memory is compared instead:
  :meth:`arshadow.session.Session.tracker_state`).

The mixin uses only the session's public attributes (``geometry``, ``exposure``, ``ground``, ``scene``)
and methods (``calibration``, ``ground_camera``).
"""

from __future__ import annotations

from collections.abc import Sequence
from datetime import datetime
from typing import TYPE_CHECKING, Any

import numpy as np

from .errors import UsageError
from .lights.spec import parse_light

if TYPE_CHECKING:
    from .engine import CalibrationState
    from .estimate.match import ExposureMatch
    from .plan import SceneGeometry
    from .scene import Scene

__all__ = ["History"]


class History:
    """The frame-to-frame memory of a :class:`arshadow.session.Session` (see the module)."""

    #: ``(static lights, sun tracks)`` that :meth:`set_time` moves, or None
    _sun: tuple[list[Any], list[Any]] | None = None

    if TYPE_CHECKING:  # provided by arshadow.session.Session
        geometry: SceneGeometry
        exposure: ExposureMatch | None
        ground: Any
        scene: Scene

        def calibration(self, width: int, height: int) -> CalibrationState: ...

        def ground_camera(self, cam_from_marker: Any) -> np.ndarray: ...

    # -- lights over time -----------------------------------------------------------------------------
    def set_lights(self, lights: Sequence[Any]) -> int:
        """Replace the lights (spec strings or :class:`arshadow.lights.spec.Light`), keeping the cached geometry
        of the lights that stay (:meth:`arshadow.plan.SceneGeometry.set_lights`); returns the number of
        (sample) lights to recompute."""
        return self.geometry.set_lights([parse_light(s) if isinstance(s, str) else s for s in lights])

    @property
    def sun_tracks(self) -> list[Any]:
        """The sun tracks :meth:`set_time` moves (the spec's time-lapse, or :meth:`use_sun_tracks`)."""
        return [] if self._sun is None else list(self._sun[1])

    @property
    def time_lapse(self) -> tuple[Any, float] | None:
        """``(start datetime, speed)`` of the spec's time-lapse, or None."""
        return self.scene.time_lapse

    def use_sun_tracks(self, tracks: Sequence[Any], static: Sequence[Any] = ()) -> None:
        """Let :meth:`set_time` move the sun: ``tracks`` (:func:`arshadow.lights.spec.parse_sun_track`) plus fixed
        ``static`` lights."""
        self._sun = (list(static), list(tracks))

    def set_time(self, when: datetime) -> list[Any]:
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
        self.geometry.set_lights(list(static) + [tr.light(f) for tr, f in zip(tracks, frames)])
        return frames

    # -- the exposure match over frames -----------------------------------------------------------------
    def exposure_gap(self) -> None:
        """A video frame without the marker, not rendered: the exposure match's smoothing counts it (a long
        loss restarts it, :data:`arshadow.estimate.exposure.RESTART_AFTER`). No-op when the match is off."""
        if self.exposure is not None:
            self.exposure.missing()

    def observe_exposure(self, image: np.ndarray, cam_from_marker: np.ndarray, marker: Any = None) -> None:
        """Measure the marker's paper on a frame that is not rendered (a video chunk's primer: the frames
        before it, decided but not composited), so that the exposure match's smoothing over frames starts
        where the run over those frames would be. No-op when the match is off.

        Parameters
        ----------
        image : (H, W, 3) uint8
            BGR frame (at least the paper's pixels, :meth:`arshadow.session.Session.exposure_region`).
        cam_from_marker : (4, 4) float64
            The frame's decided pose.
        marker : arshadow.tracking.pose.MarkerPose, optional
            The frame's tracked pose (its marker id).
        """
        if self.exposure is None:
            return
        cal = self.calibration(image.shape[1], image.shape[0])
        cfw = self.ground_camera(cam_from_marker)
        mfg = None if self.ground.is_marker else self.ground.marker_from_ground
        self.exposure.frame_gain(image, cal.intrinsics, cfw, marker, self.geometry, mfg)

    # -- saved state ------------------------------------------------------------------------------------
    def state(self) -> dict[str, Any]:
        """The history later frames depend on, picklable: the current lights with their cached silhouettes
        and volumes, the sun tracks' recompute schedule and the exposure match's smoothing.
        :meth:`restore` it (here or in another process's session of the same spec) to go on exactly as
        this session would."""
        return {
            "geometry": self.geometry.state(),
            "sun_tracks": None if self._sun is None else [tr.state() for tr in self._sun[1]],
            "exposure": None if self.exposure is None else self.exposure.state(),
        }

    def restore(self, state: dict[str, Any]) -> None:
        """Set the history saved by :meth:`state`."""
        self.geometry.restore(state["geometry"])
        if self.exposure is not None:
            self.exposure.restore(state.get("exposure"))
        if state.get("sun_tracks") is not None and self._sun is not None:
            for tr, st in zip(self._sun[1], state["sun_tracks"]):
                tr.restore(st)
