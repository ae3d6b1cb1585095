"""Input guards shared by the pure modules. They raise typed errors, never ``assert``."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from .errors import ShapeError


def check_shape(a: npt.ArrayLike, spec: str, name: str = "array") -> np.ndarray:
    """Check that ``a`` has the shape described by ``spec`` and return it as an ndarray.

    Parameters
    ----------
    a : array_like
        The value to check.
    spec : str
        Comma-separated dimensions, each an integer or a name for "any size", e.g. ``"N,3"`` or ``"3,3"``.
    name : str
        Used in the error message.

    Returns
    -------
    np.ndarray
        ``np.asarray(a)``.

    Examples
    --------
    >>> check_shape([[0.0, 1.0, 2.0]], "N,3", "points").shape
    (1, 3)
    """
    arr = np.asarray(a)
    dims = [d.strip() for d in spec.split(",") if d.strip()]
    ok = arr.ndim == len(dims) and all((not d.isdigit()) or arr.shape[i] == int(d) for i, d in enumerate(dims))
    if not ok:
        raise ShapeError(f"{name} has the wrong shape", actual_shape=arr.shape, expected_shape=f"({spec})")
    return arr


def check_finite(a: npt.ArrayLike, name: str = "array") -> np.ndarray:
    """Raise :class:`ShapeError` naming ``name`` if ``a`` holds NaN or inf; return it as float64."""
    arr = np.asarray(a, dtype=np.float64)
    if not np.all(np.isfinite(arr)):
        bad = int(np.count_nonzero(~np.isfinite(arr)))
        raise ShapeError(f"{name} contains {bad} non-finite value(s) (NaN or inf)")
    return arr
