"""Lights and the sun.

- :mod:`arshadow.lights.spec`: ``Light``, ``parse_light`` (point / directional / sun / soft specs),
  ``parse_sun_track``, ``SunLightTrack``.
- :mod:`arshadow.lights.sun`: the sun's position (NREL SPA) and ``SunTrack`` (a time-lapse schedule).

This module imports neither (``arshadow.lights.sun`` does not need ``arshadow.lights.spec``).
"""
