"""Numba stencils for the (weighted) screened Poisson normal equations of Eq. 18-19.

Energy (Hua et al. 2019, Eq. 18, weighted form of Lehtinen et al. 2013's reference solver)::

    E(I) = sum w0 (I - I0)^2 + sum wx (Dx I - Gx)^2 + sum wy (Dy I - Gy)^2

with ``w0`` already holding ``alpha^2`` times the primal weights. Its normal equations are
``A I = b`` with ``A = W0 + Dx^T Wx Dx + Dy^T Wy Dy`` and ``b = W0 I0 + Dx^T Wx Gx + Dy^T Wy Gy``.
The masked last column of ``wx`` and last row of ``wy`` are 0, so no stencil needs a boundary case
beyond "the neighbour exists". All arrays are H x W x C float64; loops run in parallel over rows,
each row writing only its own output (and its own slot of a per-row partial sum).
"""
from __future__ import annotations

import numpy as np
from numba import prange

from gdlearn.reconstruct._jit import kernel

__all__ = ["normal_rhs", "apply_normal", "dot_channels", "cg_update", "cg_direction",
           "irls_residual_lengths", "l1_energy", "uniform_rhs", "uniform_residual"]


@kernel
def normal_rhs(i0, gx, gy, w0, wx, wy, out):
    """out = W0 I0 + Dx^T Wx Gx + Dy^T Wy Gy;  (Dx^T v)[y, x] = v[y, x-1] - v[y, x]."""
    h, w, c = i0.shape
    for y in prange(h):
        for x in range(w):
            for k in range(c):
                v = (w0[y, x, k] * i0[y, x, k] - wx[y, x, k] * gx[y, x, k]
                     - wy[y, x, k] * gy[y, x, k])
                if x > 0:
                    v += wx[y, x - 1, k] * gx[y, x - 1, k]
                if y > 0:
                    v += wy[y - 1, x, k] * gy[y - 1, x, k]
                out[y, x, k] = v
    return out


@kernel
def apply_normal(p, w0, wx, wy, out):
    """out = A p and return p^T A p per channel (both needed by each conjugate-gradient step)."""
    h, w, c = p.shape
    rows = np.zeros((h, c))
    for y in prange(h):
        for x in range(w):
            for k in range(c):
                pc = p[y, x, k]
                v = w0[y, x, k] * pc
                if x + 1 < w:
                    v += wx[y, x, k] * (pc - p[y, x + 1, k])
                if x > 0:
                    v += wx[y, x - 1, k] * (pc - p[y, x - 1, k])
                if y + 1 < h:
                    v += wy[y, x, k] * (pc - p[y + 1, x, k])
                if y > 0:
                    v += wy[y - 1, x, k] * (pc - p[y - 1, x, k])
                out[y, x, k] = v
                rows[y, k] += pc * v
    return rows.sum(axis=0)


@kernel
def dot_channels(a, b):
    """Per-channel inner products sum_{y,x} a[y,x,k] b[y,x,k], shape (C,)."""
    h, w, c = a.shape
    rows = np.zeros((h, c))
    for y in prange(h):
        for x in range(w):
            for k in range(c):
                rows[y, k] += a[y, x, k] * b[y, x, k]
    return rows.sum(axis=0)


@kernel
def cg_update(x, r, p, ap, a):
    """x += a p, r -= a Ap (a per channel); return r^T r per channel."""
    h, w, c = x.shape
    rows = np.zeros((h, c))
    for y in prange(h):
        for i in range(w):
            for k in range(c):
                x[y, i, k] += a[k] * p[y, i, k]
                rv = r[y, i, k] - a[k] * ap[y, i, k]
                r[y, i, k] = rv
                rows[y, k] += rv * rv
    return rows.sum(axis=0)


@kernel
def cg_direction(p, z, beta):
    """p = z + beta p (beta per channel)."""
    h, w, c = p.shape
    for y in prange(h):
        for i in range(w):
            for k in range(c):
                p[y, i, k] = z[y, i, k] + beta[k] * p[y, i, k]


@kernel
def irls_residual_lengths(img, i0, gx, gy, alpha, v0, vx, vy, e0, ex, ey):
    """Colour-vector lengths of the three residuals of the L1 energy, per pixel (H x W each).

    e0 = |alpha (I - I0)|, ex = |Dx I - Gx|, ey = |Dy I - Gy|; channels that are missing (validity
    0) contribute nothing, as in the reference solver's per-pixel RGB ``length(e)``.
    """
    h, w, c = img.shape
    for y in prange(h):
        for x in range(w):
            s0 = 0.0
            sx = 0.0
            sy = 0.0
            for k in range(c):
                d0 = alpha * (img[y, x, k] - i0[y, x, k])
                s0 += v0[y, x, k] * d0 * d0
                if x + 1 < w:
                    dx = img[y, x + 1, k] - img[y, x, k] - gx[y, x, k]
                    sx += vx[y, x, k] * dx * dx
                if y + 1 < h:
                    dy = img[y + 1, x, k] - img[y, x, k] - gy[y, x, k]
                    sy += vy[y, x, k] * dy * dy
            e0[y, x] = np.sqrt(s0)
            ex[y, x] = np.sqrt(sx)
            ey[y, x] = np.sqrt(sy)


def l1_energy(e0, ex, ey) -> float:
    """The L1 energy of Eq. 18 (n = 1): sum of the residual lengths."""
    return float(e0.sum() + ex.sum() + ey.sum())


@kernel
def uniform_rhs(i0, gx, gy, a2, out):
    """out = a2 I0 + Dx^T Gx + Dy^T Gy for unit weights, reading no masked entry of gx / gy."""
    h, w, c = i0.shape
    for y in prange(h):
        for x in range(w):
            for k in range(c):
                v = a2 * i0[y, x, k]
                if x + 1 < w:
                    v -= gx[y, x, k]
                if x > 0:
                    v += gx[y, x - 1, k]
                if y + 1 < h:
                    v -= gy[y, x, k]
                if y > 0:
                    v += gy[y - 1, x, k]
                out[y, x, k] = v
    return out


@kernel
def uniform_residual(img, b, a2):
    """(||b - (a2 + L) I||^2, ||b||^2) with the Neumann Laplacian L, without temporaries."""
    h, w, c = img.shape
    rr = np.zeros(h)
    bb = np.zeros(h)
    for y in prange(h):
        for x in range(w):
            for k in range(c):
                ic = img[y, x, k]
                v = a2 * ic
                if x + 1 < w:
                    v += ic - img[y, x + 1, k]
                if x > 0:
                    v += ic - img[y, x - 1, k]
                if y + 1 < h:
                    v += ic - img[y + 1, x, k]
                if y > 0:
                    v += ic - img[y - 1, x, k]
                d = b[y, x, k] - v
                rr[y] += d * d
                bb[y] += b[y, x, k] * b[y, x, k]
    return rr.sum(), bb.sum()


@kernel
def sum_inverse_lengths(e0, ex, ey, eps, qmax):
    """sum over the defined terms of (1 / (e + eps)) / qmax (scaled so it cannot overflow)."""
    h, w = e0.shape
    rows = np.zeros(h)
    for y in prange(h):
        s = 0.0
        for x in range(w):
            s += 1.0 / ((e0[y, x] + eps) * qmax)
            if x + 1 < w:
                s += 1.0 / ((ex[y, x] + eps) * qmax)
            if y + 1 < h:
                s += 1.0 / ((ey[y, x] + eps) * qmax)
        rows[y] = s
    return rows.sum()


@kernel
def fill_irls_weights(e0, ex, ey, eps, s, a2, v0, vx, vy, w0, wx, wy):
    """IRLS term weights s / (|e| + eps) shared by the channels, times validity (alpha^2 on w0)."""
    h, w, c = w0.shape
    for y in prange(h):
        for x in range(w):
            q0 = a2 * s / (e0[y, x] + eps)
            qx = s / (ex[y, x] + eps)
            qy = s / (ey[y, x] + eps)
            for k in range(c):
                w0[y, x, k] = q0 * v0[y, x, k]
                wx[y, x, k] = qx * vx[y, x, k]
                wy[y, x, k] = qy * vy[y, x, k]


@kernel
def normal_diagonal(w0, wx, wy, out):
    """diag(A) = w0 + the weights of the (up to four) differences touching the pixel."""
    h, w, c = w0.shape
    for y in prange(h):
        for x in range(w):
            for k in range(c):
                v = w0[y, x, k] + wx[y, x, k] + wy[y, x, k]
                if x > 0:
                    v += wx[y, x - 1, k]
                if y > 0:
                    v += wy[y - 1, x, k]
                out[y, x, k] = v
    return out
