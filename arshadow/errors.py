"""Typed errors. Every error a user can cause is an :class:`ArshadowError` with a one-line message
that names the file or value and the problem; the command line prints that line and no traceback."""

import errno


class ArshadowError(Exception):
    """Base class of every error arshadow raises on purpose."""


class UsageError(ArshadowError, ValueError):
    """A bad option or argument (exit status 2)."""


class ShapeError(ArshadowError, ValueError):
    """An array has the wrong shape or dtype.

    Parameters
    ----------
    msg : str
        What is wrong.
    actual_shape, expected_shape : tuple or str, optional
        Shown in the message when given.
    """

    def __init__(self, msg: str, actual_shape: object = None, expected_shape: object = None) -> None:
        if actual_shape is not None or expected_shape is not None:
            msg = f"{msg} (expected shape {expected_shape}, got {actual_shape})"
        super().__init__(msg)
        self.actual_shape = actual_shape
        self.expected_shape = expected_shape


class CalibrationError(ArshadowError, ValueError):
    """A calibration file is missing, unreadable, incomplete or invalid, or does not fit the image."""


class ImageError(ArshadowError, ValueError):
    """An image or video cannot be read, or has an unusable size or format."""


class MarkerNotFoundError(ArshadowError):
    """No marker (or not the requested id / board) was found in an image."""


class MeshError(ArshadowError, ValueError):
    """A mesh cannot be loaded or is unusable (empty, NaN, all faces degenerate)."""


class LightError(ArshadowError, ValueError):
    """A light specification is malformed or physically impossible for the scene."""


class GLContextError(ArshadowError, RuntimeError):
    """No OpenGL context could be created (the message names the missing library or backend)."""


class EstimateError(ArshadowError, ValueError):
    """The light (or the exposure) cannot be measured from the photos: no usable shadow of the probe, the
    probe or its shadow out of view, an ambiguous fit. The message names the reason."""


class BatchStoppedError(ArshadowError, RuntimeError):
    """A batch cannot go on: the Dask scheduler was lost, the output disk is full. What was finished is
    kept (done records, video chunks): the message says to rerun the same command to resume."""


class OutputSpaceError(ImageError):
    """An output cannot be written because its disk is full (``ENOSPC``) or over quota (``EDQUOT``)."""


def write_error(msg: str, exc: BaseException) -> ImageError:
    """The error of a failed write: :class:`OutputSpaceError` when ``exc`` (an ``OSError`` or FFmpeg
    error, with ``errno``) says the disk is full, else :class:`ImageError`.

    >>> type(write_error("out.mp4: cannot write", OSError(errno.ENOSPC, "No space left on device"))).__name__
    'OutputSpaceError'
    """
    full = getattr(exc, "errno", None) in (errno.ENOSPC, errno.EDQUOT)
    return (OutputSpaceError if full else ImageError)(msg)
