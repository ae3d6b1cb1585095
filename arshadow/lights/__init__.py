"""Lights and the sun.

- :mod:`arshadow.lights.spec`: ``Light``, ``parse_light`` (point / directional / sun / soft specs),
  ``parse_sun_track``, ``SunLightTrack``.
- :mod:`arshadow.lights.area`: ``sample_area_light`` (a light of non-zero radius as stratified hard lights).
- :mod:`arshadow.lights.sun`: the sun's position and ``SunTrack`` (a time-lapse schedule), on
  :mod:`arshadow.lights.spa` (the NREL SPA algorithm itself, pure numpy).

This module imports neither (``arshadow.lights.sun`` does not need ``arshadow.lights.spec``).
"""
