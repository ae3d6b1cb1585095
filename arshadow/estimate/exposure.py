"""Exposure and white balance from the printed marker: its white paper and black ink as a grey card.

The marker's cells are known (its dictionary bits): every white cell is paper, every black cell ink. The
photo is decoded from sRGB to linear light; each cell is sampled at 3 x 3 points inside its central half
(bilinear, distortion honoured), away from the blurred cell edges. The lit paper is the median of the white
cells whose luminance is within 15 % of the brightest white cells (cells in a shadow are dropped); the ink
the median of the black cells. Pure numpy / OpenCV.

The result is the linear RGB that the camera recorded for lit paper: a virtual object of the paper's
colour (``--color 255,255,255``) lit like the paper must come out with exactly that value.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import cv2
import numpy as np

from ..camera.model import Intrinsics
from ..compose.composite import SRGB_TO_LINEAR
from ..errors import ArshadowError
from ..tracking.dictionary import get_dictionary, marker_bits

__all__ = [
    "LUMA",
    "Exposure",
    "ExposureError",
    "ExposureSmoother",
    "MIN_PAPER_CONTRAST",
    "measure_exposure",
    "paper_region",
    "sample_linear",
    "smooth_exposures",
]

#: Rec. 709 luminance weights of linear RGB
LUMA = np.array([0.2126, 0.7152, 0.0722])


class ExposureError(ArshadowError, ValueError):
    """The marker's paper cannot be measured (too few lit, unsaturated white cells)."""


@dataclass(frozen=True)
class Exposure:
    """The marker's paper and ink as the camera recorded them.

    Attributes
    ----------
    paper_rgb : (3,) float
        Linear RGB of the lit white paper (0..1 of the camera's range).
    ink_rgb : (3,) float
        Linear RGB of the black ink.
    white_cells : int
        Lit white cells used.
    saturated : bool
        Some paper samples are clipped (over-exposed): ``paper_rgb`` is then a lower bound.
    """

    paper_rgb: tuple
    ink_rgb: tuple
    white_cells: int
    saturated: bool = False

    @property
    def white_balance(self) -> tuple:
        """Per-channel gains (R, G, B) that make the paper grey, green = 1."""
        p = np.asarray(self.paper_rgb)
        return tuple(float(p[1] / max(c, 1e-9)) for c in p)

    @property
    def contrast(self) -> float:
        """Paper / ink luminance (Rec. 709 weights)."""
        return float(LUMA @ np.asarray(self.paper_rgb) / max(LUMA @ np.asarray(self.ink_rgb), 1e-9))

    def to_dict(self) -> dict:
        return {
            "paper_rgb": [round(float(v), 6) for v in self.paper_rgb],
            "ink_rgb": [round(float(v), 6) for v in self.ink_rgb],
            "white_balance": [round(v, 6) for v in self.white_balance],
            "contrast": round(self.contrast, 3),
            "white_cells": int(self.white_cells),
            "saturated": bool(self.saturated),
        }

    @classmethod
    def from_dict(cls, d: dict) -> Exposure:
        return cls(
            tuple(float(v) for v in d["paper_rgb"]),
            tuple(float(v) for v in d["ink_rgb"]),
            int(d.get("white_cells", 0)),
            bool(d.get("saturated", False)),
        )


def sample_linear(image_bgr: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear samples of a BGR uint8 photo in linear RGB: uv (n, 2) float pixels -> (n, 3) float32 RGB
    (NaN outside the image)."""
    lin = cv2.LUT(image_bgr, SRGB_TO_LINEAR)
    return _remap_points(lin, uv)[:, ::-1]


def _remap_points(img: np.ndarray, uv: np.ndarray) -> np.ndarray:
    uv = np.asarray(uv, np.float32).reshape(-1, 1, 2)
    out = cv2.remap(
        img, uv[:, :, 0], uv[:, :, 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=(np.nan,) * 4
    ).reshape(len(uv), -1)
    H, W = img.shape[:2]
    bad = ~((uv[:, 0, 0] >= 0) & (uv[:, 0, 0] <= W - 1) & (uv[:, 0, 1] >= 0) & (uv[:, 0, 1] <= H - 1))
    out[bad] = np.nan
    return out


def _crop_to(image: np.ndarray, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The part of ``image`` around the finite points ``uv`` (n, 2) (+ 3 px, inside the image) and the points
    in its pixels: a point is inside the crop exactly when it is inside the image."""
    H, W = image.shape[:2]
    fin = np.all(np.isfinite(uv), axis=1)
    if not fin.any():
        return image, uv
    lo = np.floor(uv[fin].min(axis=0)).astype(int) - 3
    hi = np.ceil(uv[fin].max(axis=0)).astype(int) + 4
    x0, y0 = max(int(lo[0]), 0), max(int(lo[1]), 0)
    x1, y1 = min(int(hi[0]), W), min(int(hi[1]), H)
    if x1 - x0 < 2 or y1 - y0 < 2:
        return image, uv
    return image[y0:y1, x0:x1], uv - np.array([x0, y0], np.float64)


def _cell_points(bits: np.ndarray, length: float) -> tuple[np.ndarray, np.ndarray]:
    """World points (3 x 3 per cell, central half) of every cell: ((c*c*9, 3) float64, (c*c,) bool white);
    rows of cells top to bottom, then columns, then the 3 x 3 points row by row."""
    c = bits.shape[0]
    cell = length / c
    off = (np.array([-1.0, 0.0, 1.0]) * 0.25) * cell
    r, k, dy, dx = np.meshgrid(np.arange(c), np.arange(c), off, off, indexing="ij")
    cx = -length / 2 + (k + 0.5) * cell
    cy = length / 2 - (r + 0.5) * cell
    pts = np.stack([cx + dx, cy + dy, np.zeros_like(dx)], axis=-1).reshape(-1, 3)
    return pts, bits.ravel().astype(bool)


@functools.lru_cache(maxsize=64)
def _marker_cells(dictionary: str, marker_id: int, length: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_cell_points` of one marker, computed once per (dictionary name, id, side): video frames and
    photo sets measure the same marker again and again."""
    return _cell_points(marker_bits(get_dictionary(dictionary), marker_id), length)


def paper_region(
    intrinsics: Intrinsics,
    cam_from_world: np.ndarray,
    marker_length: float,
    dictionary: str = "DICT_6X6_250",
    marker_id: int = 0,
) -> tuple | None:
    """``(x0, y0, w, h)``: the pixels :func:`measure_exposure` reads for this marker pose (its sample points'
    box + 3 px, inside the image), or None when none of them is in front of the camera. A caller that
    converts only part of a frame (the video engine's ROI) converts this too."""
    if isinstance(dictionary, str):
        pts, _ = _marker_cells(dictionary, int(marker_id), float(marker_length))
    else:
        pts, _ = _cell_points(marker_bits(get_dictionary(dictionary), int(marker_id)), float(marker_length))
    uv = intrinsics.project(pts, cam_from_world)
    fin = np.all(np.isfinite(uv), axis=1)
    if not fin.any():
        return None
    W, H = intrinsics.width, intrinsics.height
    lo = np.floor(uv[fin].min(axis=0)).astype(int) - 3
    hi = np.ceil(uv[fin].max(axis=0)).astype(int) + 4
    x0, y0 = max(int(lo[0]), 0), max(int(lo[1]), 0)
    x1, y1 = min(int(hi[0]), W), min(int(hi[1]), H)
    return None if x1 <= x0 or y1 <= y0 else (x0, y0, x1 - x0, y1 - y0)


#: fewest paper / ink luminance (:attr:`Exposure.contrast`) of a measurement that is taken: the real 5-fps
#: clip (shared/realvideo/aruco_single_paroj) measures a median of 74; its frames at 0.98-2.8 are blurred
#: swings, ambiguous poses and another marker's cells, where the "paper" is not the paper
MIN_PAPER_CONTRAST = 3.0


def measure_exposure(
    image_bgr: np.ndarray,
    intrinsics: Intrinsics,
    cam_from_world: np.ndarray,
    marker_length: float,
    dictionary: str = "DICT_6X6_250",
    marker_id: int = 0,
    min_cells: int = 3,
) -> Exposure:
    """Measure the lit paper and the ink of the detected marker in a photo.

    Parameters
    ----------
    image_bgr : (H, W, 3) uint8
        The photo (sRGB).
    intrinsics : Intrinsics
        The photo's camera (its size).
    cam_from_world : (4, 4) float64
        The marker's pose (world = marker frame, the marker centred on the origin).
    marker_length : float
        The marker's side, metres.
    dictionary, marker_id
        Which marker (its bits tell white cells from black ones).
    min_cells : int
        Fewest lit white cells accepted.

    Returns
    -------
    Exposure

    Raises
    ------
    ExposureError
        Fewer than ``min_cells`` white cells are in the image and lit, or the white cells are not brighter
        than the black ones by :data:`MIN_PAPER_CONTRAST` (the cells read are not the marker's).
    """
    if isinstance(dictionary, str):
        pts, white = _marker_cells(dictionary, int(marker_id), float(marker_length))
    else:
        pts, white = _cell_points(marker_bits(get_dictionary(dictionary), int(marker_id)), float(marker_length))
    uv = intrinsics.project(pts, cam_from_world)
    image_bgr, uv = _crop_to(image_bgr, uv)  # only the marker's pixels are decoded (once per video frame)
    rgb = sample_linear(image_bgr, uv).reshape(len(white), 9, 3)
    raw = _remap_points(image_bgr.astype(np.float32), uv).reshape(len(white), 9, 3)
    finite = np.isfinite(rgb)
    if finite.all():  # the usual case: np.median, several times faster than np.nanmedian, same values
        cell = np.median(rgb, axis=1)
    else:
        cell = np.nanmedian(rgb, axis=1) if finite.any() else np.full((len(white), 3), np.nan)
    ok = np.all(np.isfinite(cell), axis=1)
    lum = cell @ LUMA
    w_ok = white & ok
    if np.count_nonzero(w_ok) < 3:
        raise ExposureError("the marker's white cells are not in the image: cannot measure its paper")
    top = np.percentile(lum[w_ok], 90)
    lit = w_ok & (lum >= 0.85 * top)
    if np.count_nonzero(lit) < min_cells:
        raise ExposureError(
            f"fewer than {min_cells} lit white cells on the marker (a shadow on it?): cannot measure its paper"
        )
    paper = np.median(cell[lit], axis=0)
    b_ok = ~white & ok
    ink = np.median(cell[b_ok], axis=0) if b_ok.any() else np.zeros(3)
    saturated = bool(np.nanmax(raw[lit]) >= 254.5)
    out = Exposure(tuple(float(v) for v in paper), tuple(float(v) for v in ink), int(np.count_nonzero(lit)), saturated)
    if b_ok.any() and out.contrast < MIN_PAPER_CONTRAST:
        raise ExposureError(
            f"the marker's white cells are not brighter than its black ones (paper / ink {out.contrast:.2f} < "
            f"{MIN_PAPER_CONTRAST:g}): the marker is hidden, blurred, or not the one the pose says "
            "(--marker-id, --dictionary): cannot measure its paper"
        )
    return out


def smooth_exposures(measurements: list[Exposure | None], time_constant: float = 5.0, jump: float = 0.15) -> list:
    """Smooth a video's per-frame measurements, following auto-exposure changes.

    A one-pole filter in log space with ``time_constant`` frames; a change of the paper's luminance by more
    than ``jump`` (relative) that persists for 3 frames resets the filter (a new exposure, followed at once).
    ``None`` entries (marker not found) repeat the last smoothed value; after :data:`RESTART_AFTER` of them
    in a row the next measurement starts the filter afresh (a new shot).

    Parameters
    ----------
    measurements : list of Exposure or None
    time_constant : float
        Frames.
    jump : float

    Returns
    -------
    list of Exposure or None
        Same length.

    Examples
    --------
    >>> e = [Exposure((0.5, 0.5, 0.5), (0.02,) * 3, 20)] * 3 + [Exposure((0.8, 0.8, 0.8), (0.03,) * 3, 20)] * 4
    >>> [round(x.paper_rgb[0], 3) for x in smooth_exposures(e)]
    [0.5, 0.5, 0.5, 0.544, 0.8, 0.8, 0.8]
    """
    sm = ExposureSmoother(time_constant, jump)
    return [sm.update(m) for m in measurements]


#: frames in a row without a measurement after which the video's exposure smoothing starts afresh (the
#: pose stream's default hold): a marker lost for longer is a new shot, whose exposure may have changed
RESTART_AFTER = 12


class ExposureSmoother:
    """:func:`smooth_exposures` one frame at a time (a video's render loop): :meth:`update` with each
    frame's measurement (or None) returns the smoothed one; :meth:`state` / :meth:`restore` carry the filter
    between processes (parallel video chunks).

    >>> sm = ExposureSmoother()
    >>> [round(sm.update(Exposure((v,) * 3, (0.02,) * 3, 20)).paper_rgb[0], 3) for v in (0.5, 0.5, 0.8, 0.8)]
    [0.5, 0.5, 0.544, 0.8]
    """

    def __init__(self, time_constant: float = 5.0, jump: float = 0.15, restart_after: int = RESTART_AFTER):
        self.a = 1.0 - math.exp(-1.0 / max(float(time_constant), 1e-6))
        self.jump = float(jump)
        self.restart_after = int(restart_after)
        self._state: np.ndarray | None = None
        self._pending = 0
        self._missing = 0  # frames in a row without a measurement
        self._last: Exposure | None = None

    def update(self, m: Exposure | None) -> Exposure | None:
        """The smoothed measurement after frame measurement ``m`` (None: the last smoothed one). After
        ``restart_after`` frames in a row without one (the marker lost, :meth:`missing` frames included)
        the next measurement starts the filter afresh, as a new shot."""
        if m is None:
            self._missing += 1
            return self._last
        x = np.log(np.maximum(np.r_[m.paper_rgb, m.ink_rgb], 1e-6))
        if self._missing >= self.restart_after:
            self._state, self._pending = None, 0
        self._missing = 0
        if self._state is None:
            self._state = x
        else:
            far = abs(np.mean(x[:3] - self._state[:3])) > math.log1p(self.jump)
            self._pending = self._pending + 1 if far else 0
            if self._pending >= 2:  # a new exposure: followed at once
                self._state, self._pending = x, 0
            else:
                self._state = self._state + self.a * (x - self._state)
        v = np.exp(self._state)
        self._last = Exposure(
            tuple(float(t) for t in v[:3]), tuple(float(t) for t in v[3:]), m.white_cells, m.saturated
        )
        return self._last

    def missing(self) -> None:
        """A frame without the marker that is not measured at all (not rendered: ``no_marker``)."""
        self._missing += 1

    def state(self) -> dict:
        return {
            "state": None if self._state is None else self._state.tolist(),
            "pending": self._pending,
            "missing": self._missing,
            "last": None if self._last is None else self._last.to_dict(),
        }

    def restore(self, st: dict) -> None:
        self._state = None if st.get("state") is None else np.asarray(st["state"], np.float64)
        self._pending = int(st.get("pending", 0))
        self._missing = int(st.get("missing", 0))
        self._last = None if st.get("last") is None else Exposure.from_dict(st["last"])
