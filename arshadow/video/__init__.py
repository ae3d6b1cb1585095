"""Video and batches, built on the Python API (:class:`arshadow.Session`).

- :mod:`arshadow.video.engine`: the threaded decode -> track + render -> encode engine, over
  :mod:`arshadow.video.decode` (readers, the decode loop), :mod:`arshadow.video.framejob` (one frame
  tracked, decided, composited, reported) and :mod:`arshadow.video.encode` (the encode loop, atomic outputs).
- :mod:`arshadow.video.temporal`: pose smoothing and the streaming IPPE chooser (``PoseStream``).
- :mod:`arshadow.video.chooser`: the look-ahead IPPE branch chooser (``TemporalPoseChooser``).
- :mod:`arshadow.video.avio`: PyAV reader and atomic writer (H.264, audio kept, FFV1 masks).
- :mod:`arshadow.video.batch`: resumable batches of photos and videos, locally or on Dask.
"""
