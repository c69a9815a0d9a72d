"""Weights of the weighted control variates (Hua et al. 2019, Sec. 5.2, Eq. 20-22).

Variances from two half-buffers (``halves=``) are pooled over each pixel's 3 x 3 window
(``variance_pool=1``, :func:`gdlearn.reconstruct.variances_from_halves`): each estimate
becomes the larger of itself and its window's median (primal) or mean (gradients). The per-pixel
estimate (A - B)^2 / 4 has one degree of freedom: in a pixel whose two halves happen to agree it is
near zero, Eq. 21 then trusts that pixel's identities almost alone, and the early snapshots of a
progressive render can end up worse than the primal image. A window is far steadier; the maximum
with the pixel's own estimate keeps an isolated noisy pixel (a firefly, the light's edge) from
being averaged into trust; and the primal's window takes the median because a pixel's variance
jumps with the image at a light's rim -- a mean there lends the dark pixels beside a light the
light's variance, weights them nearly uniformly and spreads the light's noise (measured on the accuracy chapter's toy image and on gpt-replay frames of three scenes:
``benchmarks/README.md``, "variance pooling").

The kernels: :func:`weights` turns the variances into the normalised Eq. 21-22 weights of each
pixel's four neighbour identities (the self weight is what remains), :func:`weighted_step` runs one
Eq. 20 iteration with them. :mod:`gdlearn.reconstruct.control_variates` drives both.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from gdlearn.reconstruct._jit import kernel

__all__ = ["weights", "weighted_step"]


@njit(cache=True)
def _normalise(s, present, out):
    """Eq. 21 for one pixel: w_q = s_q^-2 / sum_r s_r^-2 over the present terms, computed as
    (m / s_q) / sum (m / s_r) with m = min s so that zero variances (exact terms) and variances
    from 1e-12 to 1e12 neither divide by zero nor overflow."""
    m = np.inf
    for i in range(5):
        if present[i] and s[i] < m:
            m = s[i]
    total = 0.0
    for i in range(5):
        if not present[i]:
            out[i] = 0.0
        elif m > 0.0:
            out[i] = m / s[i]
        else:
            out[i] = 1.0 if s[i] == 0.0 else 0.0
        total += out[i]
    for i in range(5):
        out[i] = out[i] / total if total > 0.0 else (1.0 if i == 0 else 0.0)


@kernel
def weights(v0, vx, vy, ok0, okx, oky, gx, gy, divisor, wl, wr, wt, wb, off):
    """Normalised Eq. 21-22 weights of the four neighbour identities and the constant part
    off_p = sum_q w_pq <I_p - I_q>. The self weight is 1 - (wl + wr + wt + wb)."""
    h, w, c = v0.shape
    for y in prange(h):
        s = np.empty(5)
        present = np.zeros(5, dtype=np.bool_)
        ws = np.empty(5)
        for x in range(w):
            for k in range(c):
                vp = v0[y, x, k] / divisor
                s[0] = vp
                present[0] = ok0[y, x, k] > 0.0
                present[1] = x > 0 and okx[y, x - 1, k] > 0.0
                s[1] = vp + vx[y, x - 1, k] if x > 0 else 0.0
                present[2] = okx[y, x, k] > 0.0
                s[2] = vp + vx[y, x, k]
                present[3] = y > 0 and oky[y - 1, x, k] > 0.0
                s[3] = vp + vy[y - 1, x, k] if y > 0 else 0.0
                present[4] = oky[y, x, k] > 0.0
                s[4] = vp + vy[y, x, k]
                _normalise(s, present, ws)
                wl[y, x, k] = ws[1]
                wr[y, x, k] = ws[2]
                wt[y, x, k] = ws[3]
                wb[y, x, k] = ws[4]
                o = -ws[2] * gx[y, x, k] - ws[4] * gy[y, x, k]
                if x > 0:
                    o += ws[1] * gx[y, x - 1, k]
                if y > 0:
                    o += ws[3] * gy[y - 1, x, k]
                off[y, x, k] = o


@kernel
def weighted_step(img, wl, wr, wt, wb, off, out):
    """One Eq. 20 iteration with precomputed weights; returns the sum of squared changes."""
    h, w, c = img.shape
    rows = np.zeros(h)
    for y in prange(h):
        for x in range(w):
            for k in range(c):
                ic = img[y, x, k]
                v = ic + off[y, x, k]
                if x > 0:
                    v += wl[y, x, k] * (img[y, x - 1, k] - ic)
                if x + 1 < w:
                    v += wr[y, x, k] * (img[y, x + 1, k] - ic)
                if y > 0:
                    v += wt[y, x, k] * (img[y - 1, x, k] - ic)
                if y + 1 < h:
                    v += wb[y, x, k] * (img[y + 1, x, k] - ic)
                d = v - ic
                rows[y] += d * d
                out[y, x, k] = v
    return rows.sum()
