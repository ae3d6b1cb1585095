"""The marker's paper on the ground grid: the light estimate's second albedo class.

The estimate's evidence (:mod:`arshadow.estimate.shadow`) is high-passed per albedo class, floor or paper, so
that the step between the printed sheet and the floor is not read as a shadow's. The paper class must end
at the sheet's edge, never at a shadow's: a class boundary along the probe's shadow removes the shadow's
step from the fit (docs/light.md, "Evidence").
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from .exposure import LUMA

__all__ = ["PAPER_EDGE_DROP", "PAPER_LIT", "PAPER_REACH", "PAPER_RING", "paper_cells"]

#: lit paper is at least this share of the measured paper's luminance (a lamp's fall-off
#: across the sheet; a grey floor of reflectance 0.25 is 0.3 of a paper's 0.83)
PAPER_LIT = 0.5
#: the paper looked for within this many marker sides of the marker's centre
PAPER_REACH = 2.5
#: the sheet's edge is a drop of the luminance below this share of the paper's just inside it
#: (a printer paper's 0.8 against a floor's 0.1-0.45)
PAPER_EDGE_DROP = 0.6
#: the quiet zone every printed marker has, as a multiple of its half-side (one cell of
#: a 6 x 6 marker's 8 is 1.25 x the half-side from the centre)
PAPER_RING = (1.08, 1.25)


def paper_cells(
    xy: np.ndarray, rgb: np.ndarray, used: np.ndarray, paper_rgb: np.ndarray | Sequence[float], marker_length: float
) -> np.ndarray:
    """The grid's cells on the marker's paper, ``(ny, nx) bool``: the used cells inside the bounding rectangle
    (in the marker's axes) of the lit paper connected to the marker, grown over a shadowed margin.

    Lit paper is neutral like the measured paper and at least :data:`PAPER_LIT` of its luminance; the
    8-connected regions of it within :data:`PAPER_REACH` marker sides that reach the marker's quiet zone
    (:data:`PAPER_RING`; any such region when the grid does not hold the quiet zone) make the sheet. Their
    bounding rectangle grows, side by side, over rows of paper in a shadow that covers a whole side of the
    margin, as far as the sheet's edges carry on (:func:`_grow_sheet`), and every used cell in it is paper,
    shadowed or not. The rectangle, not the lit cells: the paper class must end at the sheet's edge, never at
    a shadow's (a deep shadow on the paper and a neutral floor look alike, and a class boundary along the
    probe's shadow removes it from the fit's high-pass: until the sixth session of 2026-11-29 a neutral floor
    brighter than a fifth of the paper was all "paper" within 2.5 sides and the shadow's lit side the class's
    edge; docs/light.md).

    Parameters
    ----------
    xy : (ny, nx, 2) float64
        The cells' ground points (world, metres; the marker's centre at the origin, its sides along x and y).
    rgb : (ny, nx, 3) float64
        Linear RGB at each cell.
    used : (ny, nx) bool
    paper_rgb : (3,) float
        The lit paper's linear RGB (:func:`arshadow.estimate.exposure.measure_exposure`).
    marker_length : float
        The marker's side, metres.

    Examples
    --------
    >>> xs = np.arange(-0.1, 0.1001, 0.005)
    >>> xy = np.stack(np.meshgrid(xs, xs), axis=-1)
    >>> sheet = (np.abs(xy) <= 0.05).all(axis=-1)  # a 10 cm sheet round a 5 cm marker, on a grey floor
    >>> rgb = np.where(sheet[..., None], 0.75, 0.25) * np.ones(3)
    >>> rgb[(xy[..., 0] > 0.03) & (xy[..., 1] > 0.0)] *= 0.3  # a shadow over a corner of the sheet and the floor
    >>> cells = paper_cells(xy, rgb, np.ones(sheet.shape, bool), (0.75, 0.75, 0.75), 0.05)
    >>> bool((cells == sheet).all())
    True
    >>> rgb[xy[..., 0] > 0.03] *= 0.3  # and over the sheet's whole right-hand margin
    >>> bool((paper_cells(xy, rgb, np.ones(sheet.shape, bool), (0.75, 0.75, 0.75), 0.05) == sheet).all())
    True
    """
    p = np.asarray(paper_rgb, np.float64).reshape(3)
    chroma = rgb / np.maximum(rgb.sum(axis=-1, keepdims=True), 1e-9)
    half = 0.5 * float(marker_length)
    box = np.abs(xy).max(axis=-1)  # the marker frame's max-norm: squares round the marker
    near = box <= PAPER_REACH * float(marker_length)
    lum = rgb @ LUMA
    lit = used & near & (np.abs(chroma - p / p.sum()).max(axis=-1) < 0.035) & (lum >= PAPER_LIT * float(p @ LUMA))
    count, labels = cv2.connectedComponents(lit.astype(np.uint8), connectivity=8)
    ring = lit & (box > PAPER_RING[0] * half) & (box <= PAPER_RING[1] * half)
    keep = np.unique(labels[ring]) if ring.any() else np.arange(1, count)
    rows, cols = np.nonzero(np.isin(labels, keep[keep > 0]))
    if rows.size == 0:
        return np.zeros(used.shape, bool)
    rect = _grow_sheet([int(rows.min()), int(rows.max()), int(cols.min()), int(cols.max())], lum, used)
    out: np.ndarray = np.zeros(used.shape, bool)
    out[rect[0] : rect[1] + 1, rect[2] : rect[3] + 1] = True
    out &= used
    return out


def _grow_sheet(rect: list[int], lum: np.ndarray, used: np.ndarray) -> list[int]:
    """The lit paper's bounding rectangle ``[row0, row1, col0, col1]`` (inclusive, grid cells) grown outward,
    side by side, over the rows (columns) of the sheet that a shadow covers across a whole side of its margin:
    a row beyond a side is the sheet's while it carries on the sheet's two perpendicular edges, i.e. at both
    the rectangle's ``col0`` and ``col1`` (at the one of them seen) the 3 cells outside are under
    :data:`PAPER_EDGE_DROP` of the 3 inside (median luminance ``lum (ny, nx)`` over the ``used`` cells). A
    shadow dims paper and floor alike, so the sheet's edges are there in its shadow too; a neutral floor
    beside the sheet has none (at most a shadow's edge at one end)."""
    ny, nx = lum.shape

    def steps(k: int, across: bool) -> bool:  # row (column when across) k carries the sheet's edges on
        a, b = (rect[2], rect[3]) if not across else (rect[0], rect[1])
        cells = (lum[k], used[k]) if not across else (lum[:, k], used[:, k])
        seen = []
        for inside, outside in ((slice(a, a + 3), slice(max(a - 3, 0), a)), (slice(b - 2, b + 1), slice(b + 1, b + 4))):
            vin, vout = cells[0][inside][cells[1][inside]], cells[0][outside][cells[1][outside]]
            if vin.size and vout.size:
                seen.append(float(np.median(vout)) < PAPER_EDGE_DROP * float(np.median(vin)))
        return bool(seen) and all(seen)

    for side, step, limit in ((0, -1, 0), (1, 1, ny - 1), (2, -1, 0), (3, 1, nx - 1)):
        while rect[side] != limit and steps(rect[side] + step, side >= 2):
            rect[side] += step
    return rect
