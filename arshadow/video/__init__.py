"""Video and batches, built on the Python API (:class:`arshadow.Session`).

- :mod:`arshadow.video.engine`: the threaded decode -> track + render -> encode engine.
- :mod:`arshadow.video.temporal`: pose smoothing and the streaming IPPE chooser (``PoseStream``).
- :mod:`arshadow.video.avio`: PyAV reader and atomic writer (H.264, audio kept, FFV1 masks).
- :mod:`arshadow.video.cvio`: OpenCV video I/O and the look-ahead pose chooser.
- :mod:`arshadow.video.batch`: resumable batches of photos and videos, locally or on Dask.
"""
