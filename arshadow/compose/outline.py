"""The object's anti-aliased outline without MSAA: per-pixel coverage of its silhouette, in numpy.

With ``--aa 0`` the renderer samples pixel centres: a pixel the object's outline crosses is all object or
all ground, where the truth (and MSAA) mixes them. :func:`arshadow.geometry.contour.outline_segments` projects the object's
contour (the mesh edges between faces that face the camera and faces that do not: the silhouette from the
camera's centre, :func:`arshadow.geometry.silhouette.silhouette`) into the render's canvas; :func:`antialias_outline`
gives every pixel the outline crosses the exact coverage of the half-plane of its nearest contour segment
(the area of the pixel square on the object's side, :func:`box_coverage`), on the side the pixel centre's
sample found, and rewrites the layers there as MSAA's coverage would:

- ``alpha = coverage``; the premultiplied colour ``coverage x`` the object's colour (a pixel whose centre
  missed the object takes the mean colour of its neighbours whose centre is on it);
- every ground channel (the shadow mask, the ground coverage, the sky occlusion, its reflected light)
  ``(1 - coverage) x`` the ground's value (a pixel whose centre was on the object takes the mean of its
  neighbours whose centre is not).

The composite's formula then blends object and shadowed ground at the edge
(``out = color + photo x ((1 - alpha) - opacity x mask x (1 - shadow_color))``, docs/compositing.md).

Pixel coordinates: the arrays' own, pixel ``(row i, column j)`` has its centre at ``(x, y) = (j + 0.5, i +
0.5)``; for the renderer's bottom-up layers that is OpenGL's window coordinates.

Examples
--------
>>> float(box_coverage(np.array([0.0]), np.array([1.0]), np.array([0.0]))[0])  # a line through the centre
0.5
>>> float(box_coverage(np.array([0.25]), np.array([1.0]), np.array([0.0]))[0])  # a vertical edge 0.25 px off
0.75
"""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["antialias_outline", "box_coverage"]

#: the 8 neighbours (row, column offsets) a changed pixel takes its other layer's value from
_NEIGHBOURS = np.array([(-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)], np.intp)
#: the same and the pixel itself
_NEIGHBOURS9 = np.r_[_NEIGHBOURS, [(0, 0)]]


def box_coverage(t: np.ndarray, nx: np.ndarray, ny: np.ndarray) -> np.ndarray:
    """The area of the unit pixel square, centred on 0, where ``nx u + ny v <= t`` (a half-plane).

    Parameters
    ----------
    t : (k,) float64
        The line's signed offset from the pixel centre along its unit normal ``(nx, ny)``.
    nx, ny : (k,) float64
        The unit normal.

    Returns
    -------
    (k,) float64 in [0, 1]
        Exact: linear in ``t`` while the line crosses two opposite sides, quadratic where it cuts a corner;
        ``box_coverage(-t) = 1 - box_coverage(t)``.
    """
    a = np.maximum(np.abs(nx), np.abs(ny))
    b = np.minimum(np.abs(nx), np.abs(ny))
    s = np.abs(t)
    lin = 0.5 + s / np.maximum(a, 1e-12)
    corner = 1.0 - np.square(np.maximum(0.5 * (a + b) - s, 0.0)) / np.maximum(2.0 * a * b, 1e-12)
    up = np.where(s <= 0.5 * (a - b), lin, np.where(s < 0.5 * (a + b), corner, 1.0))
    up = np.clip(up, 0.5, 1.0)
    return np.where(t >= 0.0, up, 1.0 - up)


def _nearest_segments(band: np.ndarray, segments: np.ndarray) -> tuple[np.ndarray, ...]:
    """For the band pixels (``band``: (h, w) bool), the nearest of the segments that cross their square:
    ``(rows, cols, t, nx, ny)``, the pixels that have one, the signed offset of its line from their centre
    along its unit normal ``(nx, ny)`` (the normal's side chosen so that ``t >= 0``). A pixel no segment
    crosses (none within half its diagonal) is left out: it is wholly on one side."""
    h, w = band.shape
    a, b = segments[:, 0], segments[:, 1]
    d = b - a
    length = np.hypot(d[:, 0], d[:, 1])
    good = length > 1e-9
    a, d, length = a[good], d[good], length[good]
    if len(a) == 0:  # points only (an object seen edge-on, or far below a pixel)
        empty = np.zeros(0)
        return empty.astype(np.intp), empty.astype(np.intp), empty, empty, empty
    # points every <= 1 px along each segment: a pixel the segment crosses holds a point within 0.5 px, so
    # that point's pixel is the pixel or one of its 8 neighbours
    n = np.ceil(length).astype(np.intp) + 1
    seg = np.repeat(np.arange(len(a)), n)
    f = (np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)) / np.repeat(n - 1, n)
    # their pixels in the band padded by one (a point beyond the window: its nearest pixel of it, whose
    # neighbours hold those of the point's own that lie in the window)
    px = np.clip(np.floor(a[seg, 0] + f * d[seg, 0]), 0, w - 1).astype(np.intp) + 1
    py = np.clip(np.floor(a[seg, 1] + f * d[seg, 1]), 0, h - 1).astype(np.intp) + 1
    padded = np.zeros((h + 2, w + 2), np.uint8)
    padded[1:-1, 1:-1] = band
    near = cv2.dilate(padded, np.ones((3, 3), np.uint8)).ravel()
    q = py * (w + 2) + px
    keep = near[q] > 0  # only points beside the band (most of a complex mesh's contour is hidden inside)
    # (pixel, segment) once each: np.unique's sorted result (numpy 2's hashing np.unique took 10 x longer)
    key = np.sort(q[keep] * len(a) + seg[keep])
    first = np.ones(len(key), bool)
    first[1:] = key[1:] != key[:-1]
    key = key[first]
    offsets = (_NEIGHBOURS9[:, 0] * (w + 2) + _NEIGHBOURS9[:, 1])[None, :]
    cq = ((key // len(a))[:, None] + offsets).ravel()
    cs = np.repeat(key % len(a), 9)
    keep = padded.ravel()[cq] > 0
    cq, cs = cq[keep], cs[keep]
    # the squared distance from each candidate pixel's centre to its segment: a segment crosses the square
    # only within half its diagonal; the nearest per pixel
    cy, cx = cq // (w + 2) - 1, cq % (w + 2) - 1
    rx, ry = cx + 0.5 - a[cs, 0], cy + 0.5 - a[cs, 1]
    dx, dy = d[cs, 0], d[cs, 1]
    u = np.clip((rx * dx + ry * dy) / np.square(length[cs]), 0.0, 1.0)
    d2 = np.square(rx - u * dx) + np.square(ry - u * dy)
    keep = d2 <= 0.5 + 1e-9
    cq, cs, d2 = cq[keep], cs[keep], d2[keep]
    if cq.size == 0:  # no segment crosses a band pixel (an object a pixel or two across)
        empty = np.zeros(0)
        return empty.astype(np.intp), empty.astype(np.intp), empty, empty, empty
    order = np.argsort(cq * 2.0 + d2)  # by pixel, then distance (d2 <= 0.5)
    cq, cs = cq[order], cs[order]
    one = np.r_[True, cq[1:] != cq[:-1]]
    cq, cs = cq[one], cs[one]
    cy, cx = cq // (w + 2) - 1, cq % (w + 2) - 1
    nx, ny = -d[cs, 1] / length[cs], d[cs, 0] / length[cs]
    t = -((cx + 0.5 - a[cs, 0]) * nx + (cy + 0.5 - a[cs, 1]) * ny)  # the line's offset along (nx, ny)
    sign = np.where(t < 0.0, -1.0, 1.0)
    return cy, cx, t * sign, nx * sign, ny * sign


def antialias_outline(rgba: np.ndarray, ground: np.ndarray, segments: np.ndarray) -> int:
    """Give the object's outline its coverage in the layers, in place (see the module's docstring).

    Parameters
    ----------
    rgba : (h, w, 4) float32
        The object's premultiplied linear colour and its pixel-centre coverage (0 or 1: ``--aa 0``).
    ground : (h, w, c) float32
        The ground's channels (the shadow mask, the ground coverage, the sky channels), each 0 where the
        pixel centre is on the object, coverage-weighted elsewhere.
    segments : (s, 2, 2) float64
        The object's contour in the arrays' pixel coordinates (:func:`arshadow.geometry.contour.outline_segments`; pixel ``(i, j)``'s
        centre at ``(j + 0.5, i + 0.5)``).

    Returns
    -------
    int
        The pixels changed.

    Examples
    --------
    >>> rgba = np.zeros((4, 4, 4), np.float32); rgba[:, :2] = (0.5, 0.5, 0.5, 1.0)  # object on columns 0-1
    >>> ground = np.zeros((4, 4, 2), np.float32); ground[:, 2:] = (0.8, 1.0)  # shadowed ground on 2-3
    >>> edge = np.array([[[2.25, 0.0], [2.25, 4.0]]])  # the true outline: x = 2.25
    >>> antialias_outline(rgba, ground, edge)
    4
    >>> rgba[0, 2].tolist(), ground[0, 2].tolist()  # a quarter of pixel 2 is object
    ([0.125, 0.125, 0.125, 0.25], [0.6000000238418579, 0.75])
    """
    H, W = rgba.shape[:2]
    if len(segments) == 0:
        return 0
    seg = np.asarray(segments, np.float64)
    # the outline lies within the segments' box: work on that window (views) only
    x0, y0 = (max(int(np.floor(v)) - 2, 0) for v in seg.reshape(-1, 2).min(axis=0))
    x1, y1 = (int(np.ceil(v)) + 3 for v in seg.reshape(-1, 2).max(axis=0))
    x1, y1 = min(x1, W), min(y1, H)
    if x1 - x0 < 1 or y1 - y0 < 1:
        return 0
    rgba, ground = rgba[y0:y1, x0:x1], ground[y0:y1, x0:x1]
    h, w = rgba.shape[:2]
    on = (rgba[:, :, 3] >= 0.5).view(np.uint8)
    k = np.ones((3, 3), np.uint8)
    band = cv2.dilate(on, k) != cv2.erode(on, k)
    rows, cols, t, nx, ny = _nearest_segments(band, seg - (x0, y0))
    if rows.size == 0:
        return 0
    cov_same = box_coverage(t, nx, ny)  # the centre's side's share: >= 0.5
    obj = on[rows, cols].astype(bool)
    cov = np.where(obj, cov_same, 1.0 - cov_same).astype(np.float32)
    change = np.where(obj, cov < 1.0, cov > 0.0)
    rows, cols, cov, obj = rows[change], cols[change], cov[change], obj[change]
    if rows.size == 0:
        return 0
    nr = np.clip(rows[:, None] + _NEIGHBOURS[None, :, 0], 0, h - 1)
    nc = np.clip(cols[:, None] + _NEIGHBOURS[None, :, 1], 0, w - 1)
    n_on = on[nr, nc].astype(np.float32)  # (k, 8): which neighbours' centres are on the object
    # the object's straight colour: the pixel's own where its centre is on it, else its object neighbours'
    colour = rgba[rows, cols, :3]
    m = ~obj
    wts = n_on[m] / np.maximum(n_on[m].sum(1), 1.0)[:, None]
    colour[m] = np.einsum("kn,knc->kc", wts, rgba[nr[m], nc[m], :3])
    # the ground's values: its own where its centre missed the object, else its ground neighbours'
    value = ground[rows, cols]
    n_off = 1.0 - n_on[obj]
    wts = n_off / np.maximum(n_off.sum(1), 1.0)[:, None]
    value[obj] = np.einsum("kn,knc->kc", wts, ground[nr[obj], nc[obj]])
    rgba[rows, cols, :3] = colour * cov[:, None]
    rgba[rows, cols, 3] = cov
    ground[rows, cols] = value * (1.0 - cov)[:, None]
    return int(rows.size)
