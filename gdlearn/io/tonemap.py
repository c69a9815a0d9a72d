"""Tone mapping for display: linear RGB -> 8-bit sRGB.

The PNG files gdlearn writes are for looking at, never for measuring: exposure scale 2^stops, clamp
to [0, 1], then the sRGB transfer curve (IEC 61966-2-1: 12.92 x below 0.0031308, else
1.055 x^(1/2.4) - 0.055), the same curve Mitsuba 3 applies when it writes an 8-bit image.
Non-finite values become 0 so a bad pixel can never poison a picture.
"""
from __future__ import annotations

import numpy as np


def srgb_encode(x: np.ndarray) -> np.ndarray:
    """Linear [0, 1] -> sRGB-encoded [0, 1]."""
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def srgb_decode(v: np.ndarray) -> np.ndarray:
    """sRGB-encoded [0, 1] -> linear [0, 1] (inverse of :func:`srgb_encode`)."""
    v = np.asarray(v, dtype=np.float64)
    return np.where(v <= 0.04045, v / 12.92, np.power((v + 0.055) / 1.055, 2.4))


def tonemap(img: np.ndarray, exposure: float = 0.0) -> np.ndarray:
    """H x W x 3 (or H x W grey) linear float -> H x W x 3 uint8 sRGB (exposure in stops)."""
    a = np.nan_to_num(np.asarray(img, dtype=np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    if a.ndim == 2:
        a = np.repeat(a[..., None], 3, axis=2)
    return np.round(srgb_encode(a * 2.0 ** exposure) * 255.0).astype(np.uint8)
