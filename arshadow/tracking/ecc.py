"""Photometric corner refinement: the marker's known bitmap aligned to the image (``refine="ecc"``).

The edge refinement (:mod:`arshadow.tracking.refine`) fits the four border edges at their 50 % crossings.
Taken in code values, that crossing is the edge only when the blur is symmetric *in the image's code
values*; a camera blurs light (linearly) and then applies its tone curve, which moves the code-value
midpoint towards the dark side: the black square looks smaller, the pose too far (measured: 0.8-1.0 px
inwards on synthetic photos blurred by a 1 px Gaussian in linear light; docs/tracking.md). Since
2026-11-28 the edge refinement reads from the border's width which space is right and fits there
("Edges in linear light"). This module uses the whole pattern: a
template of the marker (its cells from the dictionary, the black border and half a cell of white paper
round it) is aligned to the image by OpenCV's ECC (``cv2.findTransformECC``, ``MOTION_HOMOGRAPHY``:
enhanced correlation, invariant to brightness and contrast), starting from the edge corners.

The template's blur is chosen per marker, in the image itself: at the starting alignment the image is
warped onto the template's grid and correlated with the template blurred by a Gaussian in *code values*
(as after a tone curve) and in *linear light* then encoded with the sRGB curve (as optics blur), at a few
widths; the best family's width is refined by a parabola through its neighbours. The chosen template is
what ECC aligns, with its own pre-smoothing off (``gaussFiltSize`` 1: ECC's default 5 blurs template and
image alike by ~1.1 px, which on the benchmark gave a worse scale, 0.33 instead of 0.26 mm median
translation error with 3, and 0.068 instead of 0.054 px corners on the plates with 5; docs/tracking.md).
The paper's and the ink's levels are shaded (a plane each) where the light falls off across the marker.

Lens distortion: the alignment works in pinhole pixels. A window of pinhole pixels round the marker is
sampled from the distorted image (:meth:`Intrinsics.distort_pixels`, bilinear), the homography is found
there, and the corners are distorted back.

Pixels: centres are integers (CONVENTIONS.md) in the image, the window and the template alike; a template
of ``s`` pixels per cell has its marker's top-left corner at ``(m - 0.5, m - 0.5)`` for a paper margin of
``m`` pixels.

Never worse than the edge corners by construction of the fallback: a marker whose alignment fails (ECC
does not converge, the correlation is low, a corner moves more than :data:`MAX_MOVE_PX`, the window leaves
the image) keeps its input corners, and :class:`EccRefinement` says why.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import cv2
import numpy as np
import numpy.typing as npt

from ..compose.composite import SRGB_TO_LINEAR, linear_to_srgb

if TYPE_CHECKING:
    from ..camera.model import Intrinsics

__all__ = [
    "BLUR_SIGMAS_PX",
    "MAX_MOVE_PX",
    "MIN_CORRELATION",
    "EccRefinement",
    "marker_template",
    "refine_corners_ecc",
]

#: a corner that ECC moves farther than this (pixels) from its starting (edge) corner: the start is kept
MAX_MOVE_PX = 1.5
#: ECC's final correlation below this: the alignment is not trusted (the start is kept)
MIN_CORRELATION = 0.7
#: the Gaussian widths (image pixels) the template's blur is chosen among (then refined by a parabola)
BLUR_SIGMAS_PX = (0.4, 0.7, 1.0, 1.4, 1.9, 2.5)
#: white paper round the marker in the template, in cells (the edge refinement reads 0.45 cell of it)
MARGIN_CELLS = 0.5
#: template pixels per marker cell: about the image's, within these bounds (cost grows with the square)
MIN_CELL_PX, MAX_CELL_PX = 3, 12
#: the paper's or the ink's level is shaded (a plane) when it changes by more than this share of the
#: marker's contrast across the template (a light's fall-off: on the point-lit reference plates the
#: unshaded template put corners 0.19-0.21 px off, the shaded one 0.06-0.07 px)
SHADING_MIN = 0.03
#: ECC's stopping rule: at most this many iterations, or a correlation gain under ``ECC_EPS``
ECC_ITERATIONS, ECC_EPS = 50, 1e-5
#: a float lookup table of the sRGB encoding (linear [0, 1] -> code [0, 1]) for the linear-light templates
_LUT_SIZE = 4096
_SRGB_LUT = linear_to_srgb(np.arange(_LUT_SIZE) / (_LUT_SIZE - 1.0)).astype(np.float32)


@dataclass(frozen=True)
class EccRefinement:
    """What :func:`refine_corners_ecc` returns.

    Attributes
    ----------
    corners : (n, 4, 2) float64
        The refined corners TL, TR, BR, BL (distorted pixels); a marker that fell back keeps its input corners.
    fallback : tuple of (str or None), length n
        Per marker: None when its corners are ECC's, else why its input corners were kept.
    correlation : (n,) float64
        ECC's final correlation coefficient (NaN where it did not run or failed).
    blur : tuple of (str, float) or None, length n
        The template's blur: ``("code", sigma_px)`` or ``("linear", sigma_px)`` (None where not chosen).
    """

    corners: np.ndarray
    fallback: tuple[str | None, ...]
    correlation: np.ndarray
    blur: tuple[tuple[str, float] | None, ...]


def marker_template(bits: npt.ArrayLike, cell_px: int, margin_px: int) -> tuple[np.ndarray, np.ndarray]:
    """A marker's sharp template: white (True) cells 1, black cells 0, on white paper.

    Parameters
    ----------
    bits : (c, c) bool
        The marker's cells including its black border, True = white
        (:func:`arshadow.tracking.dictionary.marker_bits`), row 0 the marker's top.
    cell_px : int
        Template pixels per cell.
    margin_px : int
        White paper round the marker, template pixels.

    Returns
    -------
    template : (T, T) float32
        ``T = c * cell_px + 2 * margin_px``.
    corners : (4, 2) float64
        The marker's outer corners TL, TR, BR, BL in template pixels (centres are integers).

    Examples
    --------
    >>> t, c = marker_template([[False, False], [False, True]], 2, 1)
    >>> t.shape, c[0].tolist(), c[2].tolist()
    ((6, 6), [0.5, 0.5], [4.5, 4.5])
    >>> t[1:5, 1:5].tolist()[3]
    [0.0, 0.0, 1.0, 1.0]
    """
    b = np.asarray(bits, bool)
    side = b.shape[0] * int(cell_px)
    t = np.ones((side + 2 * margin_px, side + 2 * margin_px), np.float32)
    t[margin_px : margin_px + side, margin_px : margin_px + side] = np.repeat(
        np.repeat(b.astype(np.float32), cell_px, axis=0), cell_px, axis=1
    )
    a = margin_px - 0.5
    return t, np.array([[a, a], [a + side, a], [a + side, a + side], [a, a + side]], np.float64)


def refine_corners_ecc(
    gray: np.ndarray,
    corners: npt.ArrayLike,
    bits: Sequence[npt.ArrayLike] | np.ndarray,
    intrinsics: Intrinsics | None = None,
    *,
    max_move_px: float = MAX_MOVE_PX,
    min_correlation: float = MIN_CORRELATION,
) -> EccRefinement:
    """Refine marker corners by aligning each marker's bitmap to the image (ECC homography).

    Parameters
    ----------
    gray : (H, W) uint8
        The photo's grey (its code values: the tone curve is modelled, not undone).
    corners : (n, 4, 2) float64
        Starting corners TL, TR, BR, BL (distorted pixels), within about a pixel (the edge refinement's).
    bits : sequence of n (c, c) bool, or one (c, c) bool for all
        Each marker's cells including the black border, True = white
        (:func:`arshadow.tracking.dictionary.marker_bits`).
    intrinsics : Intrinsics, optional
        The camera; with lens distortion the alignment is made in pinhole pixels (None: no distortion).
    max_move_px : float
        A marker whose corner moves farther than this keeps its starting corners.
    min_correlation : float
        A marker whose final correlation is lower keeps its starting corners.

    Returns
    -------
    EccRefinement

    Examples
    --------
    >>> from arshadow.camera import Intrinsics
    >>> from arshadow.synth import look_at_pose, render_marker_photo
    >>> from arshadow.tracking.dictionary import marker_bits
    >>> cam = Intrinsics(1000.0, 1000.0, 639.5, 359.5, 1280, 720)
    >>> photo = render_marker_photo(cam, look_at_pose([0.1, -0.2, 0.5], [0, 0, 0]), marker_length=0.05,
    ...                             blur_sigma=0.8, noise_sigma=2.0, seed=1)
    >>> start = photo.corners_px[0] + [[0.4, -0.3], [0.2, 0.3], [-0.3, 0.2], [0.1, -0.4]]
    >>> res = refine_corners_ecc(cv2.cvtColor(photo.image, cv2.COLOR_BGR2GRAY), start[None],
    ...                          marker_bits("DICT_6X6_250", 0), cam)
    >>> res.fallback, bool(np.abs(res.corners[0] - photo.corners_px[0]).max() < 0.1)
    ((None,), True)
    """
    img = np.asarray(gray)
    c_all = np.asarray(corners, np.float64).reshape(-1, 4, 2)
    b_arr = np.asarray(bits) if not isinstance(bits, (list, tuple)) else None
    per_marker = [np.asarray(b, bool) for b in bits] if b_arr is None or b_arr.ndim == 3 else None
    lens = intrinsics if intrinsics is not None and intrinsics.has_distortion else None
    out = c_all.copy()
    reasons: list[str | None] = []
    rhos = np.full(len(c_all), np.nan)
    blurs: list[tuple[str, float] | None] = []
    for m in range(len(c_all)):
        b = per_marker[m] if per_marker is not None else np.asarray(b_arr, bool)
        new, why, rho, blur = _align(img, c_all[m], b, lens)
        if why is None and rho < min_correlation:
            why = f"correlation {rho:.2f} under {min_correlation:g}"
        if why is None and float(np.max(np.linalg.norm(new - c_all[m], axis=1))) > max_move_px:
            move = float(np.max(np.linalg.norm(new - c_all[m], axis=1)))
            why = f"a corner moved {move:.2f} px (> {max_move_px:g})"
        if why is None:
            out[m] = new
        reasons.append(why)
        rhos[m] = rho
        blurs.append(blur)
    return EccRefinement(out, tuple(reasons), rhos, tuple(blurs))


def _align(
    img: np.ndarray, c: np.ndarray, bits: np.ndarray, lens: Intrinsics | None
) -> tuple[np.ndarray, str | None, float, tuple[str, float] | None]:
    """One marker: ``(corners (4, 2) distorted px, None or why not, correlation, blur)``."""
    q = lens.undistort_pixels(c) if lens is not None else c
    if not np.all(np.isfinite(q)):
        return c, "corners outside the lens model", np.nan, None
    n = bits.shape[0]
    side = float(np.mean(np.linalg.norm(q - np.roll(q, 1, axis=0), axis=1)))
    s = int(np.clip(round(side / n), MIN_CELL_PX, MAX_CELL_PX))
    mpx = max(2, int(round(MARGIN_CELLS * s)))
    scale = s * n / side  # template pixels per image pixel
    window = _pinhole_window(img, q, MARGIN_CELLS * side / n + 3.0, lens)
    if window is None:
        return c, "too close to the image border", np.nan, None
    crop, lo = window
    sharp, tc = marker_template(bits, s, mpx)
    size = sharp.shape[0]
    warp = cv2.getPerspectiveTransform(tc.astype(np.float32), (q - lo).astype(np.float32)).astype(np.float32)
    seen = cv2.warpPerspective(crop, warp, (size, size), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)
    if _correlation(sharp, seen) < 0:  # printed white on black: align the negative
        crop, seen = 255.0 - crop, 255.0 - seen
    tpl, blur = _choose_template(sharp, seen, s, scale)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, ECC_ITERATIONS, ECC_EPS)
    try:
        # OpenCV's stubs want an input mask; None is what the C++ default (no mask) takes
        rho, warp = cv2.findTransformECC(tpl, crop, warp, cv2.MOTION_HOMOGRAPHY, crit, None, 1)  # type: ignore[call-overload]
    except cv2.error as exc:
        return c, f"ECC failed ({getattr(exc, 'err', '') or 'OpenCV error'})", np.nan, blur
    p = cv2.perspectiveTransform(tc.reshape(-1, 1, 2), np.asarray(warp, np.float64)).reshape(4, 2) + lo
    new = lens.distort_pixels(p) if lens is not None else p
    if not np.all(np.isfinite(new)):
        return c, "ECC gave no finite corners", float(rho), blur
    return new, None, float(rho), blur


def _pinhole_window(
    img: np.ndarray, q: np.ndarray, pad: float, lens: Intrinsics | None
) -> tuple[np.ndarray, np.ndarray] | None:
    """The pinhole-pixel window round the corners ``q (4, 2)`` (pinhole px) grown by ``pad`` px:
    ``(window (h, w) float32, its top-left pinhole pixel (2,) float64)``, or None when it leaves the image.
    Window pixel (i, j) is pinhole pixel ``lo + (j, i)``; without a lens model, the image's own pixels."""
    H, W = img.shape[:2]
    lo = np.floor(q.min(axis=0) - pad)
    hi = np.ceil(q.max(axis=0) + pad)
    if lens is None:
        if lo.min() < 0 or hi[0] > W - 1 or hi[1] > H - 1:
            return None
        x0, y0, x1, y1 = (int(v) for v in (*lo, *hi))
        return img[y0 : y1 + 1, x0 : x1 + 1].astype(np.float32), lo
    src = _distortion_map(lens, lo, hi)
    if not np.all(np.isfinite(src)) or src.min() < 0 or src[..., 0].max() > W - 1 or src[..., 1].max() > H - 1:
        return None
    return cv2.remap(img, src[..., 0], src[..., 1], cv2.INTER_LINEAR).astype(np.float32), lo


def _distortion_map(lens: Intrinsics, lo: np.ndarray, hi: np.ndarray, step: int = 8) -> np.ndarray:
    """Where the distorted image sees each pinhole pixel of the window ``lo..hi`` (inclusive):
    ``(h, w, 2) float32`` distorted pixels. Exact on a grid of every ``step``-th pixel, bilinear between
    (the distortion is smooth: the interpolation errs far below 0.01 px; the grid's cost is 1/step^2)."""
    w, h = int(hi[0] - lo[0]) + 1, int(hi[1] - lo[1]) + 1
    gx = np.arange(0, w - 1 + step, step, dtype=np.float64)
    gy = np.arange(0, h - 1 + step, step, dtype=np.float64)
    xs, ys = np.meshgrid(gx + lo[0], gy + lo[1])
    coarse = lens.distort_pixels(np.stack([xs.ravel(), ys.ravel()], axis=1)).reshape(len(gy), len(gx), 2)
    rows = _lerp(coarse, h, step, axis=0)
    return _lerp(rows, w, step, axis=1).astype(np.float32)


def _lerp(a: np.ndarray, n: int, step: int, axis: int) -> np.ndarray:
    """Linear interpolation of ``a`` along ``axis`` from nodes ``0, step, 2 step, ..`` to ``0 .. n-1``."""
    t = np.arange(n) / step
    i = np.minimum(t.astype(np.intp), a.shape[axis] - 2)
    f = (t - i).reshape([-1 if k == axis else 1 for k in range(a.ndim)])
    out: np.ndarray = np.take(a, i, axis=axis) * (1.0 - f) + np.take(a, i + 1, axis=axis) * f
    return out


def _correlation(a: np.ndarray, b: np.ndarray) -> float:
    """The correlation coefficient of two same-shape arrays (what ECC maximises)."""
    x = a.ravel() - a.mean()
    y = b.ravel() - b.mean()
    return float(np.dot(x, y) / np.sqrt(float(np.dot(x, x)) * float(np.dot(y, y)) + 1e-30))


def _choose_template(sharp: np.ndarray, seen: np.ndarray, s: int, scale: float) -> tuple[np.ndarray, tuple[str, float]]:
    """The blurred, shaded template that correlates best with ``seen`` (the image warped onto the
    template's grid): ``(template (T, T) float32, (family, sigma in image px))``.

    Families: the sharp template blurred in code values; in linear light (ink at the reflectance ratio
    read off ``seen``), then sRGB-encoded. Shading: the paper's and the ink's levels are planes fitted to
    ``seen`` away from the cells' edges (a light's fall-off across the marker, which ECC's one gain and
    offset cannot follow)."""
    inner = sharp > 0.5
    dark_lvl, light_lvl = _level_planes(seen, inner, 1.5 * scale)
    dark, light = (int(np.clip(np.median(v), 1, 255)) for v in (dark_lvl, light_lvl))
    ink = min(float(SRGB_TO_LINEAR[dark] / SRGB_TO_LINEAR[max(light, dark)]), 1.0)
    linear = np.where(inner, np.float32(1.0), np.float32(ink))
    best: tuple[float, np.ndarray, tuple[str, float]] | None = None
    for family, base in (("code", sharp), ("linear", linear)):
        render = _blurred(base, scale, ink if family == "linear" else None, dark_lvl, light_lvl)
        cs = [_correlation(render(sg), seen) for sg in BLUR_SIGMAS_PX]
        k = int(np.argmax(cs))
        sg = BLUR_SIGMAS_PX[k]
        if 0 < k < len(cs) - 1:  # the vertex of the parabola through the best width and its neighbours
            a2, a1, _ = np.polyfit(BLUR_SIGMAS_PX[k - 1 : k + 2], cs[k - 1 : k + 2], 2)
            if a2 < 0:
                sg = float(np.clip(-a1 / (2.0 * a2), BLUR_SIGMAS_PX[k - 1], BLUR_SIGMAS_PX[k + 1]))
        tpl = render(sg)
        cc = _correlation(tpl, seen)
        if best is None or cc > best[0]:
            best = (cc, tpl, (family, round(float(sg), 3)))
    assert best is not None
    return best[1], best[2]


def _level_planes(seen: np.ndarray, white: np.ndarray, pure: float) -> tuple[np.ndarray, np.ndarray]:
    """The ink's and the paper's levels over the template's grid, ``(dark (T, T), light (T, T))`` float32.

    Each is a plane, least squares on ``seen``'s pixels that a Gaussian of ``pure`` template px leaves
    within 2 % of pure black / white, kept only where it changes by more than :data:`SHADING_MIN` of the
    contrast across the template (else its mean: a plane fitted to noise or to the blur's remains would
    only add error)."""
    soft = cv2.GaussianBlur(white.astype(np.float32), (0, 0), pure, borderType=cv2.BORDER_REPLICATE)
    yy, xx = np.mgrid[0 : seen.shape[0], 0 : seen.shape[1]].astype(np.float32)
    span = float(seen.shape[0])
    planes: list[np.ndarray] = []
    means: list[float] = []
    for core, half in ((soft < 0.02, soft < 0.5), (soft > 0.98, soft >= 0.5)):
        if core.sum() < 12:  # a marker too small for pure pixels: its halves
            core = half
        v = seen[core]
        a = np.column_stack([np.ones(v.size, np.float32), xx[core], yy[core]])
        coef = np.linalg.lstsq(a, v, rcond=None)[0]
        planes.append(coef)
        means.append(float(v.mean()))
    contrast = max(means[1] - means[0], 1.0)
    out = []
    for coef, mean in zip(planes, means, strict=True):
        if span * float(np.hypot(coef[1], coef[2])) > SHADING_MIN * contrast:
            out.append((coef[0] + coef[1] * xx + coef[2] * yy).astype(np.float32))
        else:
            out.append(np.full(seen.shape, mean, np.float32))
    return out[0], out[1]


def _blurred(
    base: np.ndarray, scale: float, ink: float | None, dark: np.ndarray, light: np.ndarray
) -> Callable[[float], np.ndarray]:
    """A function of sigma (image px) -> ``base`` blurred by it on the template's grid (``scale`` template
    px per image px), sRGB-encoded and rescaled to 0..1 when ``ink`` (the linear family's black) is given,
    then shaded from ``dark`` (0) to ``light`` (1)."""
    lo = float(_SRGB_LUT[int(np.clip(ink * (_LUT_SIZE - 1) + 0.5, 0, _LUT_SIZE - 1))]) if ink is not None else 0.0

    def render(sigma: float) -> np.ndarray:
        t = cv2.GaussianBlur(base, (0, 0), sigma * scale, borderType=cv2.BORDER_REPLICATE)
        if ink is not None:
            idx = np.clip(t * (_LUT_SIZE - 1) + 0.5, 0, _LUT_SIZE - 1).astype(np.intp)
            t = (_SRGB_LUT[idx] - lo) / max(1.0 - lo, 1e-6)
        out: np.ndarray = dark + (light - dark) * t
        return out

    return render
