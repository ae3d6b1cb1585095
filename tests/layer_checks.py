"""Checks of compositing layers shared by the layer tests: linear light, recombination, the largest difference."""

from __future__ import annotations

import numpy as np


def linear(codes):
    """sRGB codes (0-255) to linear light, float64."""
    c = np.asarray(codes, np.float64) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def recombine(plate_bgr, obj_rgba, shadow, over=False):
    """Independent float64 recombination: returns int BGR."""
    lin = linear(plate_bgr)[..., ::-1]
    s = np.asarray(shadow, np.float64)
    if over:
        s = (1.0 - np.asarray(obj_rgba[..., 3], np.float64)) * (1.0 - s)
    if s.ndim == 2:
        s = s[..., None]
    return srgb8(lin * s + np.asarray(obj_rgba[..., :3], np.float64))[..., ::-1]


def maxdiff(a, b):
    return int(np.abs(np.asarray(a, np.int64) - np.asarray(b, np.int64)).max())


def srgb8(x):
    x = np.clip(np.asarray(x, np.float64), 0.0, 1.0)
    c = np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
    return np.floor(c * 255.0 + 0.5).astype(np.int64)
