"""Score a composite against a path-traced truth (the realism work): the residual of the insert's effect.

For a region R (ground pixels, object pixels, or the contact band), in camera-linear RGB::

    residual = sum_R |S(composite - truth)| / sum_R |S(truth - plate)|

0 is perfect, 1 is as bad as not inserting anything. ``S`` smooths a little (a Gaussian of
:data:`SMOOTH_SIGMA_PX`, normalised within the ground and within the object separately, so that the object's
edge does not bleed into the ground) so that the path tracer's per-pixel noise does not dominate: without it
64 spp noise alone scores about 0.14. The composite is taken as the plate plus the insert's change,
``plate + (decode(composite8) - decode(plate8))``: the 8-bit plate's quantisation cancels where arshadow
changes nothing. R is limited to where the insert changes something: ground pixels where the smoothed
truth (or composite) differs from the plate by more than :data:`CHANGE_NOISE_K` times the path tracer's noise
and :data:`CHANGE_REL` of the plate (dilated by 2 px: :func:`change_map`), the contact band always; all object pixels. The noise floor is the same score with a
second truth (another seed) as the composite.

Numpy and OpenCV only (no Mitsuba): the committed renders are scored in the default test suite.
"""

from __future__ import annotations

import cv2
import numpy as np

from ..compose.composite import SRGB_TO_LINEAR

__all__ = [
    "SMOOTH_SIGMA_PX",
    "change_map",
    "change_threshold",
    "decode8",
    "residuals",
    "residuals_smoothed",
    "smooth_regions",
    "smooth_within",
]

#: smoothing of the differences within the ground / within the object, pixels (Gaussian sigma)
SMOOTH_SIGMA_PX = 1.5
#: a ground pixel is changed when its smoothed change exceeds this many noise sigmas
CHANGE_NOISE_K = 4.0
#: ... and this share of the plate there (summed over channels): a change under 2 % is not seen, and the
#: faint far halo of sky occlusion would otherwise make the score mostly the path tracer's noise (the noise
#: floor on the ground: 0.067 without, 0.031 with it, box_sun at 64 spp)
CHANGE_REL = 0.02


def decode8(bgr8: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 BGR sRGB codes -> (H, W, 3) float64 linear RGB."""
    rgb: np.ndarray = SRGB_TO_LINEAR[bgr8][:, :, ::-1].astype(np.float64)
    return rgb


def smooth_within(d: np.ndarray, mask: np.ndarray, sigma: float = SMOOTH_SIGMA_PX) -> np.ndarray:
    """Gaussian smoothing of ``d`` (H, W, 3) float64 normalised within ``mask`` (H, W) bool: pixels outside the
    mask neither contribute nor receive (0 there).

    >>> m = np.zeros((5, 5), bool); m[:, :2] = True
    >>> d = np.ones((5, 5, 3)); d[:, 2:] = 9.0
    >>> float(smooth_within(d, m)[:, :2].max()), float(smooth_within(d, m)[:, 2:].max())
    (1.0, 0.0)
    """
    w = mask.astype(np.float32)
    num = cv2.GaussianBlur((d * w[:, :, None]).astype(np.float32), (0, 0), sigma, borderType=cv2.BORDER_REFLECT)
    den = cv2.GaussianBlur(w, (0, 0), sigma, borderType=cv2.BORDER_REFLECT)
    out = num / np.maximum(den, 1e-6)[:, :, None]
    out[~mask] = 0.0
    return out.astype(np.float64)


def change_threshold(noise_delta: np.ndarray, masks: dict) -> float:
    """The changed-pixel threshold (sum over channels of a smoothed change): :data:`CHANGE_NOISE_K` times the
    robust sigma of the smoothed single-render noise, from ``noise_delta`` = truth2 - truth (H, W, 3) (the
    difference of two renders has sqrt(2) times one render's noise)."""
    s = np.abs(smooth_regions(noise_delta, masks)).sum(axis=2)[masks["ground"]]
    sigma = 1.4826 * float(np.median(s)) / np.sqrt(2.0)
    return float(CHANGE_NOISE_K * max(sigma, 1e-6))


def change_map(noise_threshold: float, plate: np.ndarray) -> np.ndarray:
    """(H, W) float64: the per-pixel changed threshold, the larger of ``noise_threshold``
    (:func:`change_threshold`) and :data:`CHANGE_REL` times the plate's camera-linear RGB (H, W, 3) summed."""
    out: np.ndarray = np.maximum(noise_threshold, CHANGE_REL * np.asarray(plate, np.float64).sum(axis=2))
    return out


def smooth_regions(d: np.ndarray, masks: dict) -> np.ndarray:
    """``d`` (H, W, 3) smoothed within the ground and within the object separately (0 elsewhere): the ``S`` of
    the residual (linear: S(a - b) = S(a) - S(b), so the truth's change can be stored smoothed)."""
    out: np.ndarray = smooth_within(d, masks["ground"]) + smooth_within(d, masks["object"])
    return out


def residuals(
    delta_comp: np.ndarray,
    delta_truth: np.ndarray,
    masks: dict,
    threshold: float | np.ndarray,
    comp_changes: bool = True,
) -> dict:
    """The residuals of an insert, per region (:func:`residuals_smoothed` of the smoothed changes).

    Parameters
    ----------
    delta_comp : (H, W, 3) float64
        The composite's change of the plate, camera-linear RGB.
    delta_truth : (H, W, 3) float64
        truth - plate, camera-linear RGB.
    masks : dict
        ``ground``, ``object``, ``contact``: (H, W) bool (:func:`arshadow.bench.reference_scene.scene_masks`).
    threshold : float or (H, W) float64
        The changed-pixel threshold (:func:`change_map`).
    comp_changes : bool
        Count the ground the composite changes beyond the threshold too (a shadow in the wrong place); False
        for a noisy composite (the second truth: the noise floor), whose noise would spread the region.
    """
    return residuals_smoothed(
        smooth_regions(delta_comp, masks), smooth_regions(delta_truth, masks), masks, threshold, comp_changes
    )


def residuals_smoothed(
    sc: np.ndarray, st: np.ndarray, masks: dict, threshold: float | np.ndarray, comp_changes: bool = True
) -> dict:
    """The residuals from the smoothed changes ``sc`` = S(composite - plate) and ``st`` = S(truth - plate),
    (H, W, 3) float64; other parameters as :func:`residuals`.

    Returns
    -------
    dict
        ``ground``, ``contact``, ``object``: the residual (float, nan for an empty region); ``*_px``: the
        region's pixel count.

    Examples
    --------
    >>> m = {"ground": np.ones((9, 9), bool), "object": np.zeros((9, 9), bool), "contact": np.zeros((9, 9), bool)}
    >>> st = np.zeros((9, 9, 3)); st[3:6, 3:6] = -0.2
    >>> residuals_smoothed(st, st, m, 0.01)["ground"], residuals_smoothed(0 * st, st, m, 0.01)["ground"]
    (0.0, 1.0)
    """
    err = np.abs(sc - st).sum(axis=2)
    ref = np.abs(st).sum(axis=2)
    changed = ref > threshold
    if comp_changes:
        changed |= np.abs(sc).sum(axis=2) > threshold
    changed = cv2.dilate(changed.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    regions = {
        "ground": masks["ground"] & (changed | masks["contact"]),
        "contact": masks["contact"],
        "object": masks["object"],
    }
    out: dict = {}
    for name, r in regions.items():
        den = float(ref[r].sum())
        out[name] = float(err[r].sum()) / den if den > 0 else float("nan")
        out[f"{name}_px"] = int(r.sum())
    return out
