"""Marker and board tracking (OpenCV, no GL).

One responsibility per module, in dependency order:

- :mod:`arshadow.tracking.dictionary`: ArUco dictionaries (names, files), marker bits, the marker frame.
- :mod:`arshadow.tracking.board`: the board model and board files (grid, ChArUco), the board frame.
- :mod:`arshadow.tracking.luma`: a video frame's limited-range luma as grey, converted where it is read.
- :mod:`arshadow.tracking.detect`: detector parameters, ``detect_markers``, ``Detection``, ``to_gray``.
- :mod:`arshadow.tracking.refine`: edge-based corner refinement (``refine="edge"``).
- :mod:`arshadow.tracking.ecc`: the marker's bitmap aligned to the image from the edge corners (``refine="ecc"``).
- :mod:`arshadow.tracking.quality`: the single-marker quality gates (ambiguity, blur, occlusion).
- :mod:`arshadow.tracking.pose`: planar pose (IPPE + LM) and ``MarkerPose``.
- :mod:`arshadow.tracking.fastdetect`: the half-resolution detection pass (``MarkerTracker(detector="fast")``).
- :mod:`arshadow.tracking.roi_track`: detection in a window around the last marker, full-frame fallback
  (``MarkerTracker(track_roi=True)``, video).
- :mod:`arshadow.tracking.tracker`: ``MarkerTracker`` (detect + pose in one image).
- :mod:`arshadow.tracking.calibration`: camera calibration from chessboard / ChArUco views.
"""
