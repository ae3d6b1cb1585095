"""A marker map's inputs and file: the detections of photos and videos, and the map written as a board file.

The file is a generic board file (``type: markers``, calib/README.md: what ``--board`` reads), each
marker's corners in the map's frame (the reference marker's), with the fit's residuals beside them: per
marker ``rms_px`` (corner RMS reprojection error after the bundle adjustment) and ``frames_seen``, and a
``map`` block (reference id, frames, total RMS, what was rejected). Readers of board files ignore those.
"""

from __future__ import annotations

import itertools
import os
import threading
from collections.abc import Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import cv2
import numpy as np

from ..camera.cvstorage import write_storage
from ..camera.model import Intrinsics
from ..errors import ImageError, UsageError
from ..io import read_image
from .detect import Detection, to_gray
from .fastdetect import fast_detector_params
from .mapping import MarkerMap, Observations
from .tracker import MarkerTracker

__all__ = ["VIDEO_SUFFIXES", "MAX_MAP_FRAMES", "observe_inputs", "write_map"]

VIDEO_SUFFIXES = (".mp4", ".m4v", ".mov", ".mkv", ".avi", ".webm", ".mpg", ".mpeg", ".ts", ".mts", ".wmv", ".flv")
#: frames read for a map at most (a longer video is sampled evenly)
MAX_MAP_FRAMES = 600


def _video_frames(path: Path, max_frames: int) -> Iterator[np.ndarray]:
    """Grey frames of a video, evenly sampled down to ``max_frames`` (decoding all, converting those used)."""
    cap = cv2.VideoCapture(str(path))
    if not cap.isOpened():
        raise ImageError(f"{path}: cannot open the video")
    try:
        n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
        step = max(1, -(-n // max_frames)) if n > 0 else 1
        k = 0
        while True:
            if not cap.grab():
                break
            if k % step == 0:
                ok, frame = cap.retrieve()
                if ok:
                    yield to_gray(frame)
            k += 1
    finally:
        cap.release()


def observe_inputs(
    inputs: Iterable[str | os.PathLike[str]],
    intrinsics: Intrinsics,
    *,
    dictionary: str | None = None,
    refine: str = "edge",
    inverted: bool | None = None,
    max_frames: int = MAX_MAP_FRAMES,
    workers: int | None = None,
) -> Observations:
    """Detect every marker in photos and videos (videos by extension, :data:`VIDEO_SUFFIXES`).

    Parameters
    ----------
    inputs : sequence of path
    intrinsics : Intrinsics
        The frames must have its size or its aspect ratio (all the same size).
    dictionary : str, optional
    refine : str
        Corner refinement of the detections (default ``"edge"``: unbiased, docs/video.md).
    max_frames : int
        Frames read in all, at most (shared between the videos).
    workers : int, optional
        Detection threads (default: one per core).

    Returns
    -------
    Observations
        Frames numbered in input order.

    Raises
    ------
    ImageError
        An unreadable photo or video, frames of different sizes.
    """
    local = threading.local()

    def detect(gray: np.ndarray) -> Detection:
        if not hasattr(local, "tracker"):  # one tracker per thread (a tracker remembers its misses)
            # one threshold window (the fast pass's, ~1.5x cheaper; a map does not need every marker of
            # every frame) and edge-fitted corners: subpix corners put the synthetic clip's markers 2-6 mm off
            local.tracker = MarkerTracker(
                intrinsics,
                dictionary=dictionary,
                marker_length=1.0,
                refine=refine,
                inverted=inverted,
                detector_params=fast_detector_params(),
            )
        tracker: MarkerTracker = local.tracker
        return tracker.detect(gray)

    frames = _frames(inputs, intrinsics, max_frames)
    dets: list = []
    n = max(1, int(workers or os.cpu_count() or 1))
    with ThreadPoolExecutor(n) as pool:  # OpenCV and numpy release the GIL: detection runs on every core
        while True:
            chunk = list(itertools.islice(frames, 16 * n))
            if not chunk:
                break
            size = (chunk[0].shape[1], chunk[0].shape[0])
            dets.extend(pool.map(detect, chunk))
    if not dets:
        raise UsageError("no frames to learn a map from")
    return Observations.from_detections(dets, size)


def _frames(inputs: Iterable[str | os.PathLike[str]], intrinsics: Intrinsics, max_frames: int) -> Iterator[np.ndarray]:
    """Grey frames of photos and videos (videos evenly sampled, :data:`MAX_MAP_FRAMES` in all), all of one
    size that the calibration takes."""
    items = [Path(p) for p in inputs]
    videos = [p for p in items if p.suffix.lower() in VIDEO_SUFFIXES]
    per_video = max(1, max_frames // max(1, len(videos)))
    size = None
    for p in items:
        for g in _video_frames(p, per_video) if p in videos else [to_gray(read_image(p))]:
            s = (g.shape[1], g.shape[0])
            if size is not None and s != size:
                raise ImageError(f"{p}: {s[0]}x{s[1]} frames among {size[0]}x{size[1]} ones: one map, one camera")
            if size is None:
                intrinsics.for_image(*s)  # a size the calibration cannot take: its error, naming the sizes
            size = s
            yield g


def _write_floats(fs: cv2.FileStorage, key: str, values: Iterable[float], flow: bool = True) -> None:
    fs.startWriteStruct(key, cv2.FileNode_SEQ | (cv2.FileNode_FLOW if flow else 0))
    for v in values:
        fs.write("", float(v))
    fs.endWriteStruct()


def write_map(mmap: MarkerMap, path: str | os.PathLike[str]) -> Path:
    """Write ``mmap`` as a ``type: markers`` board file with its residuals (YAML/JSON by extension,
    atomically). Returns the path."""
    p = Path(path)
    with write_storage(p, "map file", UsageError) as fs:
        fs.write("type", "markers")
        fs.write("dictionary", str(mmap.dictionary))
        fs.startWriteStruct("markers", cv2.FileNode_SEQ)
        for mid in sorted(mmap.corners):
            fs.startWriteStruct("", cv2.FileNode_MAP)
            fs.write("id", int(mid))
            fs.startWriteStruct("corners", cv2.FileNode_SEQ)
            for q in np.asarray(mmap.corners[mid], np.float64):
                _write_floats(fs, "", q)
            fs.endWriteStruct()
            rms = mmap.rms_px.get(mid, float("nan"))
            fs.write("rms_px", float(rms) if np.isfinite(rms) else -1.0)
            fs.write("frames_seen", int(mmap.frames_seen.get(mid, 0)))
            fs.endWriteStruct()
        fs.endWriteStruct()
        fs.startWriteStruct("map", cv2.FileNode_MAP)
        fs.write("reference_id", int(mmap.reference_id))
        fs.write("frames", int(mmap.n_frames))
        fs.write("frames_used", int(mmap.frames_used))
        fs.write("rms_px", float(mmap.rms_total_px))
        fs.startWriteStruct("rejected", cv2.FileNode_SEQ)
        for r in mmap.rejected[:200]:
            fs.write("", str(r))
        fs.endWriteStruct()
        fs.endWriteStruct()
    return p
