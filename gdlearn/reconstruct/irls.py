"""L1 reconstruction by IRLS with a multigrid-preconditioned inner solve (the default path of
:func:`gdlearn.reconstruct.poisson_l1`).

Energy (Eq. 18 with n = 1, the reference solver's convention, see :mod:`.poisson`)::

    E(I) = sum_p alpha |I_p - I0_p| + |(Dx I - Gx)_p| + |(Dy I - Gy)_p|

Reweighting k (the reference solver's L1D preset): term weights ``q = 1 / (|e| + eps_k)`` from the
current residual lengths ``e`` (normalised to mean 1), then one weighted least-squares step. How
that step is solved is what makes this path fast:

* **Correction form.** The float64 residual of the reweighted normal equations
  ``r = b - A x = W0 (I0 - x) - Dx^T Wx (Dx x - Gx) - Dy^T Wy (Dy x - Gy)`` comes from one stencil
  pass over the data; only the correction ``A d = r`` is solved, in float32 (half the memory
  traffic), and ``x += d`` stays float64. The next reweighting recomputes the residual in float64,
  so float32 round-off in ``d`` is corrected as in iterative refinement.
* **Shared weights.** The reference solver reweights a pixel's RGB residual as one vector, so on
  complete data the channels share one weight per term: weights are 1 x H x W (a third of the
  memory). Missing (non-finite) input makes them per channel (weight 0 where missing).
* **Multigrid preconditioner** (:class:`.multigrid.Multigrid`) built on the actual weights, which
  span up to ``1 / eps`` (1e7 by the last reweighting) -- where the DCT solve of the mean weight
  needs tens of CG steps, the V-cycle needs a few.
* **Stopping rule per reweighting**: CG stops when the correction's residual has dropped by
  ``tol`` relative to its start (not relative to ``b``: the start of a warm-started reweighting
  is already close, and a tolerance relative to ``b`` stops after zero steps once eps is small).

All of it runs on the padded planar layout of :mod:`.planar`.
"""
from __future__ import annotations

import numpy as np
from numba import prange

from ._jit import kernel
from .multigrid import Multigrid
from .planar import from_planar, pcg_planar, to_planar

__all__ = ["irls_multigrid"]


@kernel(fastmath=True)
def _lengths(img, i0, gx, gy, alpha, v0, vx, vy, e0, ex, ey):
    """Colour lengths of the three residuals per pixel (padded H+2 x W+2, frame 0), validity of
    Cv = 1 or C channels; returns (L1 energy, largest length). Squares are summed in row buffers
    (cache-resident) so that e0 / ex / ey are written once."""
    c, hp, wp = img.shape
    cv = v0.shape[0]
    rows = np.zeros((hp, 2))
    for y in prange(1, hp - 1):
        s0 = np.zeros(wp)
        sx = np.zeros(wp)
        sy = np.zeros(wp)
        for k in range(c):
            kv = k if cv > 1 else 0
            for x in range(1, wp - 1):
                ic = img[k, y, x]
                d0 = alpha * (ic - i0[k, y, x])
                dx = img[k, y, x + 1] - ic - gx[k, y, x]
                dy = img[k, y + 1, x] - ic - gy[k, y, x]
                s0[x] += v0[kv, y, x] * d0 * d0
                sx[x] += vx[kv, y, x] * dx * dx
                sy[x] += vy[kv, y, x] * dy * dy
        tot = 0.0
        big = 0.0
        for x in range(1, wp - 1):
            a, b, d = np.sqrt(s0[x]), np.sqrt(sx[x]), np.sqrt(sy[x])
            e0[y, x] = a
            ex[y, x] = b
            ey[y, x] = d
            tot += a + b + d
            big = max(big, max(a, max(b, d)))
        rows[y, 0] = tot
        rows[y, 1] = big
    return rows[:, 0].sum(), rows[:, 1].max()


@kernel(fastmath=True)
def _sum_inverse(e0, ex, ey, eps, qmax):
    """sum of (1 / (e + eps)) / qmax over the defined terms (every pixel; edges with a right /
    lower neighbour), scaled by 1 / qmax so that it cannot overflow."""
    hp, wp = e0.shape
    rows = np.zeros(hp)
    for y in prange(1, hp - 1):
        s = 0.0
        for x in range(1, wp - 1):
            s += 1.0 / ((e0[y, x] + eps) * qmax)
        for x in range(1, wp - 2):
            s += 1.0 / ((ex[y, x] + eps) * qmax)
        if y < hp - 2:
            for x in range(1, wp - 1):
                s += 1.0 / ((ey[y, x] + eps) * qmax)
        rows[y] = s
    return rows.sum()


@kernel(fastmath=True)
def _fill_weights(e0, ex, ey, eps, s, a2, v0, vx, vy, w0, wx, wy):
    """IRLS weights s / (|e| + eps) times validity (alpha^2 on w0); frame and masked terms 0."""
    cv, hp, wp = v0.shape
    for y in prange(hp):
        for k in range(cv):
            for x in range(wp):
                w0[k, y, x] = a2 * s / (e0[y, x] + eps) * v0[k, y, x]
                wx[k, y, x] = s / (ex[y, x] + eps) * vx[k, y, x]
                wy[k, y, x] = s / (ey[y, x] + eps) * vy[k, y, x]


@kernel(fastmath=True)
def _residual(img, i0, gx, gy, w0, wx, wy, out):
    """out = b - A img on the interior (out may be float32) and ||b||^2 per channel, with
    b = W0 I0 + Dx^T Wx Gx + Dy^T Wy Gy."""
    c, hp, wp = img.shape
    cw = w0.shape[0]
    rows = np.zeros((hp, c))
    for y in prange(1, hp - 1):
        for k in range(c):
            kw = k if cw > 1 else 0
            s = 0.0
            for x in range(1, wp - 1):
                ic = img[k, y, x]
                q0, qr, ql = w0[kw, y, x], wx[kw, y, x], wx[kw, y, x - 1]
                qd, qu = wy[kw, y, x], wy[kw, y - 1, x]
                gr, gl, gd, gu = gx[k, y, x], gx[k, y, x - 1], gy[k, y, x], gy[k, y - 1, x]
                r = (q0 * (i0[k, y, x] - ic) + qr * (img[k, y, x + 1] - ic - gr)
                     - ql * (ic - img[k, y, x - 1] - gl) + qd * (img[k, y + 1, x] - ic - gd)
                     - qu * (ic - img[k, y - 1, x] - gu))
                b = q0 * i0[k, y, x] - qr * gr + ql * gl - qd * gd + qu * gu
                out[k, y, x] = r
                s += b * b
            rows[y, k] = s
    return rows.sum(axis=0)


def planar_problem(prob):
    """(i0, gx, gy, v0, vx, vy) padded planar float64: data with masked / missing entries 0, and
    validity 1 x ... (complete data: shared by the channels) or C x ... (per channel)."""
    h, w, c = prob.shape
    if prob.complete:
        data = [to_planar(a) for a in (prob.primal, prob.gx, prob.gy)]
        data[1][:, :, w] = 0.0              # the masked last column of gx may hold anything
        data[2][:, h, :] = 0.0
        ones = np.ones((h, w, 1))
        valid = [to_planar(ones) for _ in range(3)]
        valid[1][:, :, w] = 0.0
        valid[2][:, h, :] = 0.0
        return (*data, *valid)
    return tuple(to_planar(a) for a in prob.clean())


def irls_multigrid(prob, x, alpha, irls_iterations, eps0, eps_decay, cg_iterations, tol,
                   dtype=np.float32, sweeps=1):
    """Reweightings 1 .. irls_iterations - 1 from the L2 start ``x`` (H x W x C float64).

    Returns (x H x W x C, L1 energy per outer iteration incl. the start, CG steps per reweighting).
    """
    i0, gx, gy, v0, vx, vy = planar_problem(prob)
    x = to_planar(x)
    h, w, _ = prob.shape
    e0, ex, ey = (np.zeros((h + 2, w + 2)) for _ in range(3))
    energy, emax = _lengths(x, i0, gx, gy, alpha, v0, vx, vy, e0, ex, ey)
    history, inner = [energy], []
    wts = tuple(np.empty(v0.shape, dtype=dtype) for _ in range(3))
    r = np.zeros(x.shape, dtype=dtype)
    n_terms = h * w + h * max(w - 1, 0) + w * max(h - 1, 0)
    for k in range(1, irls_iterations):
        # eps = 0 (pure IRLS) must not divide by an exactly-zero residual: floor it far below the
        # largest residual; normalising to mean weight 1 divides by the largest weight first
        eps = max(eps0 * eps_decay ** (k - 1), 1e-12 * emax, 1e-300)
        qmax = 1.0 / eps
        s = n_terms / _sum_inverse(e0, ex, ey, eps, qmax) / qmax
        _fill_weights(e0, ex, ey, eps, s, alpha * alpha, v0, vx, vy, *wts)
        _residual(x, i0, gx, gy, *wts, r)
        pre = Multigrid(*wts, dtype=dtype, sweeps=sweeps)
        d, _, it = pcg_planar(r, *wts, pre, tol=tol, maxiter=cg_iterations, overwrite_b=True)
        x += d
        inner.append(it)
        energy, emax = _lengths(x, i0, gx, gy, alpha, v0, vx, vy, e0, ex, ey)
        history.append(energy)
    return from_planar(x), history, inner
