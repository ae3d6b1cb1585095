"""Marker and board tracking (OpenCV, no GL).

- :mod:`arshadow.tracking.marker`: dictionaries, boards, ``MarkerTracker`` (detection, corner refinement,
  IPPE pose, ambiguity flags), ``MarkerPose``.
- :mod:`arshadow.tracking.fastdetect`: the half-resolution detection pass (``MarkerTracker(detector=...)``).
- :mod:`arshadow.tracking.roi_track`: detection in a window around the last marker, full-frame fallback
  (``MarkerTracker(track_roi=True)``, video).
- :mod:`arshadow.tracking.calibration`: camera calibration from chessboard / ChArUco views.
"""
