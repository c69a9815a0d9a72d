"""The red-black split layout: the padded planar layout of :mod:`.planar` with each row stored as
its even columns followed by its odd columns -- the fast layout of L1's inner solve
(:mod:`.multigrid`, :mod:`.irls`; operator of Eq. 18-19, Hua et al. 2019, in weighted form).

A padded ``C x (H+2) x (W+2)`` array becomes ``C x (H+2) x 2 x Wh`` with ``Wh = (W + 3) // 2``:
``[k, Y, 0, i]`` holds padded column ``X = 2 i`` and ``[k, Y, 1, i]`` column ``X = 2 i + 1``
(pixel (y, x) sits at Y = y + 1, X = x + 1; the frame and the spare slot of an odd width hold 0).
On row Y the pixels of colour c ((X + Y) % 2 == c) are exactly half ``(c + Y) % 2``, so a
red-black Gauss-Seidel half-sweep reads and writes contiguous half rows and computes only the
points it moves -- half the arithmetic of a natural row, where the whole row was computed and every
second value stored (measured at 1280 x 720 x 3, float32, one thread: 1.25 ms against 2.5 ms).

**Neighbours as slices.** Every stencil here runs over "self" slices and reads its horizontal
neighbours from the other half with a fixed offset, so each loop indexes only ``[i]`` from 0 (what
lets LLVM vectorise it; ``a[i - 1]`` costs a negative-index test per value). For half p, with
q = 1 - p::

    self  = a[..., p, q:]     left (X - 1) = a[..., q, :]     right (X + 1) = a[..., q, 1:]

over ``n_p`` values: ``W // 2`` for p = 0 (X = 2, 4, ..), ``(W + 1) // 2`` for p = 1 (X = 1, 3, ..).
The edge weight ``wx[X]`` (edge X -> X+1) of the left edge is ``left`` of wx. Rows above and below
are the same slices of rows Y - 1 and Y + 1.

Kernels take the interior width ``w`` (the layout alone cannot tell W = 2 Wh - 3 from 2 Wh - 2)
and never write the frame: vectors and weights are allocated zeroed and keep a zero frame.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from gdlearn.reconstruct._jit import kernel

__all__ = ["split_shape", "to_split", "from_split", "apply_split", "split_operator", "half_count"]


def split_shape(c, h, w):
    """Shape of an H x W x C image in the split layout."""
    return (c, h + 2, 2, (w + 3) // 2)


@njit(cache=True)
def half_count(p, w):
    """Interior values in half p of a row of interior width w (see the module docstring)."""
    return w // 2 if p == 0 else (w + 1) // 2


@kernel
def _to_split(a, out):
    h, w, c = a.shape
    for y in prange(h):
        for x in range(w):
            for k in range(c):
                out[k, y + 1, (x + 1) % 2, (x + 1) // 2] = a[y, x, k]


@kernel
def _from_split(s, out):
    h, w, c = out.shape
    for y in prange(h):
        for x in range(w):
            for k in range(c):
                out[y, x, k] = s[k, y + 1, (x + 1) % 2, (x + 1) // 2]


def to_split(a, dtype=np.float64):
    """H x W x C -> split layout C x (H+2) x 2 x Wh (frame 0)."""
    h, w, c = a.shape
    out = np.zeros(split_shape(c, h, w), dtype=dtype)
    _to_split(np.ascontiguousarray(a), out)
    return out


def from_split(s, w, dtype=np.float64):
    """Split layout (interior width ``w``) -> H x W x C."""
    c, hp = s.shape[0], s.shape[1]
    out = np.empty((hp - 2, w, c), dtype=dtype)
    _from_split(s, out)
    return out


@kernel(fastmath=True)
def apply_split(p, w0, wx, wy, out, w, r):
    """out = A p, ``A = W0 + Dx^T Wx Dx + Dy^T Wy Dy``, on the interior (split layout, interior
    width w); returns the 4 x C inner products (p^T A p, r^T p, r^T A p, |A p|^2) per channel --
    with them a CG step needs no separate pass for r^T z or for its stopping test. (The loop is
    in the kernel body, see :mod:`.mg_kernels`.)"""
    c, hp = p.shape[0], p.shape[1]
    cw = w0.shape[0]
    rows = np.zeros((hp, 4, c))
    for y in prange(1, hp - 1):
        for k in range(c):
            kw = k if cw > 1 else 0
            pap = 0.0
            rp = 0.0
            rap = 0.0
            apap = 0.0
            for h in range(2):
                q = 1 - h
                ps, pl, pr, pu = p[k, y, h, q:], p[k, y, q], p[k, y, q, 1:], p[k, y - 1, h, q:]
                pd, rs, outs = p[k, y + 1, h, q:], r[k, y, h, q:], out[k, y, h, q:]
                w0s, wxs, wxl = w0[kw, y, h, q:], wx[kw, y, h, q:], wx[kw, y, q]
                wys, wyu = wy[kw, y, h, q:], wy[kw, y - 1, h, q:]
                for i in range(half_count(h, w)):
                    pc = ps[i]
                    v = (w0s[i] * pc + wxs[i] * (pc - pr[i]) + wxl[i] * (pc - pl[i])
                         + wys[i] * (pc - pd[i]) + wyu[i] * (pc - pu[i]))
                    outs[i] = v
                    pap += pc * v
                    rp += rs[i] * pc
                    rap += rs[i] * v
                    apap += v * v
            rows[y, 0, k] = pap
            rows[y, 1, k] = rp
            rows[y, 2, k] = rap
            rows[y, 3, k] = apap
    return rows.sum(axis=0)


def split_operator(w0, wx, wy, w):
    """The operator argument of :func:`.planar.pcg_planar` for split-layout weights (``r``
    omitted: p itself, i.e. just A p and p^T A p wanted)."""
    return lambda p, out, r=None: apply_split(p, w0, wx, wy, out, w, p if r is None else r)
