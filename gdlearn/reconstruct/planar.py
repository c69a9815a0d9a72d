"""The weighted screened Poisson operator on a padded planar layout, and conjugate gradients for
the padded layouts (this one and the red-black split layout of :mod:`.split`, which the L1 path
uses; the CG vector kernels are layout-blind).

Operator (as in :mod:`.operators`, Eq. 18-19 of Hua et al. 2019 in weighted form):
``A = W0 + Dx^T Wx Dx + Dy^T Wy Dy``.

Layout: vectors are ``C x (H+2) x (W+2)`` and weights ``Cw x (H+2) x (W+2)`` (``Cw = 1``: one
weight per pixel shared by the channels, as IRLS on complete data produces; ``Cw = C``: per
channel). Pixel (y, x) sits at [k, y+1, x+1]; the one-pixel frame holds 0 in every vector and
weight; ``wx[Y, X]`` weighs the edge (Y, X)-(Y, X+1) and ``wy[Y, X]`` the edge (Y, X)-(Y+1, X),
so the masked last column / row and the frame weigh 0. Every stencil then runs over the interior
without a boundary test and each row is a contiguous loop that LLVM vectorises (the interleaved
H x W x C kernels of :mod:`.operators` branch per value and run several times slower).
"""
from __future__ import annotations

import numpy as np
from numba import prange

from gdlearn.reconstruct._jit import kernel

__all__ = ["to_planar", "from_planar", "apply_planar", "planar_operator", "pcg_planar"]


def to_planar(a, dtype=np.float64):
    """H x W x C -> padded C x (H+2) x (W+2) (frame 0)."""
    h, w, c = a.shape
    out = np.zeros((c, h + 2, w + 2), dtype=dtype)
    out[:, 1:-1, 1:-1] = np.moveaxis(a, 2, 0)
    return out


def from_planar(p):
    """Padded C x (H+2) x (W+2) -> H x W x C float64."""
    return np.ascontiguousarray(np.moveaxis(p[:, 1:-1, 1:-1], 0, 2), dtype=np.float64)


@kernel(fastmath=True)
def apply_planar(p, w0, wx, wy, out):
    """out = A p on the interior; returns p^T A p per channel."""
    c, hp, wp = p.shape
    cw = w0.shape[0]
    rows = np.zeros((hp, c))
    for y in prange(1, hp - 1):
        for k in range(c):
            kw = k if cw > 1 else 0
            s = 0.0
            pr, pu, pd, outr = p[k, y], p[k, y - 1], p[k, y + 1], out[k, y]
            w0r, wxr, wyr, wyu = w0[kw, y], wx[kw, y], wy[kw, y], wy[kw, y - 1]
            for x in range(1, wp - 1):      # 1-D row slices: simpler addressing, faster
                pc = pr[x]
                v = (w0r[x] * pc + wxr[x] * (pc - pr[x + 1]) + wxr[x - 1] * (pc - pr[x - 1])
                     + wyr[x] * (pc - pd[x]) + wyu[x] * (pc - pu[x]))
                outr[x] = v
                s += pc * v
            rows[y, k] = s
    return rows.sum(axis=0)


@kernel(fastmath=True)
def _dot(a, b):
    """Per-channel inner products over the whole padded arrays (the frame is 0)."""
    c, hp, wp = a.shape
    rows = np.zeros((hp, c))
    for y in prange(hp):
        for k in range(c):
            s = 0.0
            ar, br = a[k, y], b[k, y]
            for x in range(wp):
                s += ar[x] * br[x]
            rows[y, k] = s
    return rows.sum(axis=0)


@kernel(fastmath=True)
def _update(x, r, p, ap, a):
    """x += a p, r -= a Ap (a per channel); returns r^T r per channel."""
    c, hp, wp = x.shape
    rows = np.zeros((hp, c))
    for y in prange(hp):
        for k in range(c):
            ak = a[k]
            s = 0.0
            xr, rr, pr, apr = x[k, y], r[k, y], p[k, y], ap[k, y]
            for i in range(wp):
                xr[i] += ak * pr[i]
            for i in range(wp):
                rv = rr[i] - ak * apr[i]
                rr[i] = rv
                s += rv * rv
            rows[y, k] = s
    return rows.sum(axis=0)


@kernel(fastmath=True)
def _axpy(x, p, a):
    """x += a p (a per channel)."""
    c, hp, wp = x.shape
    for y in prange(hp):
        for k in range(c):
            ak = a[k]
            xr, pr = x[k, y], p[k, y]
            for i in range(wp):
                xr[i] += ak * pr[i]


@kernel(fastmath=True)
def _direction(p, z, beta):
    """p = z + beta p (beta per channel)."""
    c, hp, wp = p.shape
    for y in prange(hp):
        for k in range(c):
            bk = beta[k]
            pr, zr = p[k, y], z[k, y]
            for i in range(wp):
                pr[i] = zr[i] + bk * pr[i]


def planar_operator(w0, wx, wy):
    """The operator argument of :func:`pcg_planar` for natural-layout weights (the extra inner
    products by numpy: this layout serves tests and reference, not speed)."""
    def op(p, out, r=None):
        r = p if r is None else r
        pap = apply_planar(p, w0, wx, wy, out)
        dot = [np.einsum("kyx,kyx->k", a, b, dtype=np.float64) for a, b in ((r, p), (r, out),
                                                                           (out, out))]
        return np.stack([pap, *dot])
    return op


def _rows(a):
    """A C x (H+2) x ... vector as C x (H+2) x row (a view): the vector kernels are layout-blind."""
    return a.reshape(a.shape[0], a.shape[1], -1)


def pcg_planar(b, operator, precond, tol=1e-2, maxiter=50, bnorm=None, overwrite_b=False,
               x=None, rr0=None, work=None):
    """Preconditioned CG on ``A d = b`` from d = 0, one independent system per channel, in the
    dtype of ``b`` (float32 or float64), for the padded layouts (natural or :mod:`.split`).
    ``operator(p, out, r)`` writes A p into out's interior and returns the 4 x C inner products
    (p^T A p, r^T p, r^T A p, |A p|^2) per channel (:func:`planar_operator`,
    :func:`.split.split_operator`). Stops when ||b - A d|| <= tol * bnorm (bnorm defaults to
    ||b||) or after ``maxiter`` steps. Returns (d, history of ||b - A d|| / bnorm, steps).
    ``overwrite_b``: use ``b`` as the residual's storage (saves a copy; b then holds no useful
    value). ``x``: add the steps to this array instead (e.g. the float64 iterate of an outer
    iterative refinement: no separate ``x += d`` pass) and return it as d. ``rr0``: b^T b per
    channel if the caller has it (the IRLS pass computes it with b). ``work``: a dict in which
    the vectors A p and p live across calls (same shape and dtype; their frames stay 0), so a
    caller solving many systems does not pay for fresh pages each time.

    Fused passes: the first step's r^T z is the operator's r^T p (p = z); the new residual's norm
    ``|r - a A p|^2 = r^T r - 2 a r^T A p + a^2 |A p|^2`` is known before r is updated, so the
    last step updates d alone (r is not needed after it). That prediction is trusted only while
    it keeps >= 1e-6 of r^T r (cancellation costs at most ~1e-9 of it then); deeper steps
    update r and measure it."""
    d = np.zeros_like(b) if x is None else x
    r = b if overwrite_b else b.copy()
    work = {} if work is None else work
    if work.get("ap") is None or work["ap"].shape != b.shape or work["ap"].dtype != b.dtype:
        work["ap"] = np.zeros_like(b)     # the operator writes the interior: the frame stays 0
        work["p"] = None
    ap = work["ap"]
    d3, r3, ap3 = _rows(d), _rows(r), _rows(ap)
    rr = _dot(r3, r3) if rr0 is None else np.asarray(rr0, dtype=np.float64)
    if bnorm is None:
        bnorm = float(np.sqrt(rr.sum()))
    if bnorm == 0.0:
        bnorm = 1.0                        # b = 0: measure the absolute residual instead
    history = [float(np.sqrt(rr.sum())) / bnorm]
    it = 0
    if maxiter == 0 or history[0] <= tol:
        return d, np.asarray(history), 0
    z = precond(r)
    # p may alias the preconditioner's output buffer until a second step needs z again: IRLS
    # mostly stops after one step, and the copy is a full pass over the vectors
    p = z if z is not r else z.copy()     # (an identity preconditioner returns r itself)
    rz = None
    while True:
        pap, rp, rap, apap = operator(p, ap, r)
        if rz is None:
            rz = rp                        # first step: p = z
        # a channel whose residual is already exactly 0 has pAp = 0: leave it alone
        a = np.where(pap > 0.0, rz / np.where(pap > 0.0, pap, 1.0), 0.0)
        it += 1
        rr_new = rr - 2.0 * a * rap + a * a * apap
        last = it >= maxiter or np.sqrt(max(rr_new.sum(), 0.0)) / bnorm <= tol
        if last and rr_new.sum() >= 1e-6 * rr.sum():
            _axpy(d3, _rows(p), a)
            history.append(float(np.sqrt(rr_new.sum())) / bnorm)
            break
        rr = _update(d3, r3, _rows(p), ap3, a)
        history.append(float(np.sqrt(rr.sum())) / bnorm)
        if it >= maxiter or history[-1] <= tol:
            break
        if p is z:
            if work.get("p") is None:
                work["p"] = np.empty_like(z)
            p = work["p"]
            p[...] = z
        z = precond(r)
        rz_new = _dot(r3, _rows(z))
        beta = np.where(rz > 0.0, rz_new / np.where(rz > 0.0, rz, 1.0), 0.0)
        _direction(_rows(p), _rows(z), beta)
        rz = rz_new
    return d, np.asarray(history), it
