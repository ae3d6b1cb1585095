"""What a video's summary adds to a failure, read from the video again: the other dictionaries' markers
when the marker was found in no frame (as a photo's "no marker found" message names them)."""

from __future__ import annotations

import os
from collections.abc import Sequence

import cv2

from ..errors import ArshadowError
from ..tracking.detect import markers_in_image
from .avio import AvReader

__all__ = ["other_dictionaries_hint"]

#: the frames read again for the hint (a video whose marker was never found: a few frames say enough)
HINT_FRAMES = (0, 15, 30)


def other_dictionaries_hint(
    path: str | os.PathLike[str], dictionary: str | cv2.aruco.Dictionary | None, frames: Sequence[int] = HINT_FRAMES
) -> str:
    """``"; the video has markers of other dictionaries: DICT_4X4_50 ids 0 (give --dictionary)"``, from
    the first of ``frames`` (frame indices) that shows any, or ``""`` (none, or the video unreadable).

    ``dictionary``: the one asked for (a name or ``cv2.aruco.Dictionary``), left out with its family
    (:func:`arshadow.tracking.detect.markers_in_image`)."""
    try:
        reader = AvReader(path, max_frames=max(frames) + 1)
    except (ArshadowError, OSError):
        return ""
    try:
        for fr in reader:
            if fr.index not in frames:
                continue
            other = markers_in_image(fr.image, skip=dictionary)
            if other:
                listed = "; ".join(
                    f"{n} ids {', '.join(map(str, ids[:8]))}{' ...' if len(ids) > 8 else ''}"
                    for n, ids in other.items()
                )
                return f"; the video has markers of other dictionaries: {listed} (give --dictionary)"
    except (ArshadowError, OSError):
        return ""
    finally:
        reader.close()
    return ""
