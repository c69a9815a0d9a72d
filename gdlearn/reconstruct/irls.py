"""L1 reconstruction by IRLS with a multigrid-preconditioned inner solve (the default path of
:func:`gdlearn.reconstruct.poisson_l1`).

Energy (Eq. 18 with n = 1, the reference solver's convention, see :mod:`.poisson`)::

    E(I) = sum_p alpha |I_p - I0_p| + |(Dx I - Gx)_p| + |(Dy I - Gy)_p|

Reweighting k (the reference solver's L1D preset): term weights ``q = 1 / (|e| + eps_k)`` from the
current residual lengths ``e`` (the reference normalises them to mean 1; any common factor gives
the same step, here they are scaled by eps_k into (0, 1]), then one weighted least-squares step.
How that step is solved is what makes this path fast:

* **One pass per reweighting** (:func:`irls_pass`): residual lengths, L1 energy, weights, the
  operator's inverse diagonal and the residual below come from one sweep over the data
  (previously five passes: lengths, weight sum, weights, residual, diagonal).
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
  needs tens of CG steps, the V-cycle needs a few; one symmetric-SOR sweep (omega 1.2) before
  and after each coarse correction.
* **Stopping rule per reweighting**: CG stops when the correction's residual has dropped by
  ``tol`` relative to its start (not relative to ``b``: the start of a warm-started reweighting
  is already close, and a tolerance relative to ``b`` stops after zero steps once eps is small).

All of it runs on the padded planar layout of :mod:`.planar`.
"""
from __future__ import annotations

import numpy as np
from numba import get_num_threads, njit, prange

from ._jit import kernel
from .multigrid import Multigrid
from .planar import from_planar, pcg_planar, to_planar

__all__ = ["irls_multigrid"]


@kernel(fastmath=True)
def irls_pass(img, i0, gx, gy, alpha, v0, vx, vy, eps, full, w0, wx, wy, invd, r, nch,
              complete):
    """One sweep over the data from the current iterate ``img`` (padded planar float64): the L1
    energy (Eq. 18, n = 1) and the largest residual length; with ``full``, also the IRLS weights
    of the next reweighting ``q = eps / (|e| + eps) = 1 / (1 + |e| / eps)`` times validity
    (alpha^2 on w0), the inverse diagonal of the reweighted operator (0 where it is 0) and the
    residual of its normal equations ``r = W0 (I0 - x) - Dx^T Wx (Dx x - Gx) - Dy^T Wy (Dy x - Gy)``
    in float64 (the outer residual of the iterative refinement, see the module docstring).

    The weights are the reference's ``1 / (|e| + eps)`` times eps: any common factor leaves the
    correction unchanged (A and r scale together), and this one puts them in (0, 1] without the
    extra pass a normalisation to mean 1 needs and without any risk of float32 overflow.

    The passes this replaces (lengths, weight sum, weights, residual, diagonal) each read the
    full-resolution data; here each row is read once (``nch`` chunks of rows, each with its own
    row buffers). Row y needs the weight of the edge above
    it, (y-1)-(y), which row y-1 writes: it is recomputed from the same data instead (rows are
    independent, so the loop stays parallel). Outputs are written on the interior only: their
    frames must be 0 (they are allocated zeroed once). Returns (energy, largest length)."""
    c, hp, wp = img.shape
    rows = np.zeros((hp, 2))
    # row buffers are made once per chunk of rows (nch chunks): made per row they cost as much
    # as the sweep
    nch = max(1, min(nch, hp - 2))
    for j in prange(nch):
        lens = np.zeros((4, wp))        # lengths e0, ex, ey and eu (the edge above)
        q = np.zeros((4, wp), dtype=np.float32)     # their weights
        start = 1 + j * (hp - 2) // nch
        for y in range(start, 1 + (j + 1) * (hp - 2) // nch):
            # the edge above row y is row y-1's edge below: computed only at a chunk's start
            rows[y, 0], rows[y, 1] = _lengths_row(y, img, i0, gx, gy, alpha, v0, vx, vy,
                                                  lens, full and y == start, complete)
            if full:
                _weights_row(y, i0, img, gx, gy, lens, q, alpha * alpha, eps, v0, vx, vy,
                             w0, wx, wy, invd, r)
                lens[3, :] = lens[2, :]
    return rows[:, 0].sum(), rows[:, 1].max()


@njit(cache=True, fastmath=True)
def _lengths_row(y, img, i0, gx, gy, alpha, v0, vx, vy, lens, with_eu, complete):
    """Row y of irls_pass: colour lengths of the residuals into lens (e0, ex, ey; with
    ``with_eu`` also eu, the edge above (y-1, x) - (y, x), else lens[3] must hold row y-1's ey
    already); returns (sum of the row's e0, ex, ey, largest). ``complete``: the validity is
    1 but for the masked last column of gx and last row of gy, which are zeroed after the loop
    instead of reading three validity rows (a third fewer loads in the hottest loop)."""
    c, hp, wp = img.shape
    cv = v0.shape[0]
    e0, ex, ey, eu = lens[0], lens[1], lens[2], lens[3]
    e0[:] = 0.0
    ex[:] = 0.0
    ey[:] = 0.0
    if with_eu:
        eu[:] = 0.0
    for k in range(c):
        kv = k if cv > 1 else 0
        ir, iu, idn = img[k, y], img[k, y - 1], img[k, y + 1]
        i0r, gxr, gyr, gur = i0[k, y], gx[k, y], gy[k, y], gy[k, y - 1]
        v0r, vxr, vyr, vur = v0[kv, y], vx[kv, y], vy[kv, y], vy[kv, y - 1]
        # 1-D row slices and loops with few stores: what lets LLVM vectorise them
        if complete:
            for x in range(1, wp - 1):
                ic = ir[x]
                d0 = alpha * (ic - i0r[x])
                ddx = ir[x + 1] - ic - gxr[x]
                ddy = idn[x] - ic - gyr[x]
                e0[x] += d0 * d0
                ex[x] += ddx * ddx
                ey[x] += ddy * ddy
        else:
            for x in range(1, wp - 1):
                ic = ir[x]
                d0 = alpha * (ic - i0r[x])
                ddx = ir[x + 1] - ic - gxr[x]
                ddy = idn[x] - ic - gyr[x]
                e0[x] += v0r[x] * d0 * d0
                ex[x] += vxr[x] * ddx * ddx
                ey[x] += vyr[x] * ddy * ddy
        if with_eu:
            for x in range(1, wp - 1):
                ddu = ir[x] - iu[x] - gur[x]
                eu[x] += vur[x] * ddu * ddu
    if complete:
        ex[wp - 2] = 0.0
        if y == hp - 2:
            ey[:] = 0.0
    for i in range(4 if with_eu else 3):
        li = lens[i]
        for x in range(1, wp - 1):
            li[x] = np.sqrt(li[x])
    tot = 0.0
    big = 0.0
    for x in range(1, wp - 1):
        tot += e0[x] + ex[x] + ey[x]
        big = max(big, max(e0[x], max(ex[x], ey[x])))
    return tot, big


@njit(cache=True, fastmath=True)
def _weights_row(y, i0, img, gx, gy, lens, q, a2, eps, v0, vx, vy, w0, wx, wy, invd, r):
    """Row y of irls_pass's weights ``1 / (1 + |e| / eps)``, inverse diagonal and residual, from
    the lengths (e0, ex, ey, eu in lens); q: a float32 4 x (W+2) buffer with q[1, 0] = 0 (the
    frame edge left of the first pixel). The weights are computed in float32 (they are stored
    so anyway): twice the SIMD width of float64 divisions, and 1 + |e| / eps >= 1 cannot divide
    by 0 whatever eps is."""
    c, wp = img.shape[0], img.shape[2]
    cv = v0.shape[0]
    e0, ex, ey, eu = lens[0], lens[1], lens[2], lens[3]
    q0, qx, qy, qu = q[0], q[1], q[2], q[3]
    ie = 1.0 / eps
    one = np.float32(1.0)
    a2f = np.float32(a2)
    for kw in range(cv):
        v0r, vxr, vyr, vur = v0[kw, y], vx[kw, y], vy[kw, y], vy[kw, y - 1]
        w0r, wxr, wyr, idr = w0[kw, y], wx[kw, y], wy[kw, y], invd[kw, y]
        for x in range(1, wp - 1):      # one store per loop: more stays scalar (alias checks)
            q0[x] = a2f * np.float32(v0r[x]) / (one + np.float32(e0[x] * ie))
        for x in range(1, wp - 1):
            qx[x] = np.float32(vxr[x]) / (one + np.float32(ex[x] * ie))
        for x in range(1, wp - 1):
            qy[x] = np.float32(vyr[x]) / (one + np.float32(ey[x] * ie))
        for x in range(1, wp - 1):
            qu[x] = np.float32(vur[x]) / (one + np.float32(eu[x] * ie))
        for x in range(1, wp - 1):
            w0r[x] = q0[x]
        for x in range(1, wp - 1):
            wxr[x] = qx[x]
        for x in range(1, wp - 1):
            wyr[x] = qy[x]
        for x in range(1, wp - 1):
            dg = q0[x] + qx[x] + qx[x - 1] + qy[x] + qu[x]
            idr[x] = one / dg if dg > 0.0 else 0.0
        for k in range(kw if cv > 1 else 0, kw + 1 if cv > 1 else c):
            # the residuals are recomputed from the (cache-resident) rows: cheaper than storing
            # them in the lengths loop
            i0r, ir, iu, idn, rr = i0[k, y], img[k, y], img[k, y - 1], img[k, y + 1], r[k, y]
            gxr, gyr, gur = gx[k, y], gy[k, y], gy[k, y - 1]
            for x in range(1, wp - 1):
                ic = ir[x]
                rr[x] = (q0[x] * (i0r[x] - ic) + qx[x] * (ir[x + 1] - ic - gxr[x])
                         - qx[x - 1] * (ic - ir[x - 1] - gxr[x - 1])
                         + qy[x] * (idn[x] - ic - gyr[x]) - qu[x] * (ic - iu[x] - gur[x]))


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
    """Reweightings 1 .. irls_iterations - 1 from the L2 start ``x`` (H x W x C float64);
    ``sweeps``: the V-cycle's smoothing sweeps (see :class:`.multigrid.Multigrid`).

    Returns (x H x W x C, L1 energy per outer iteration incl. the start, CG steps per reweighting).
    """
    i0, gx, gy, v0, vx, vy = planar_problem(prob)
    x = to_planar(x)
    wts = tuple(np.zeros(v0.shape, dtype=dtype) for _ in range(3))
    invd = np.zeros(v0.shape, dtype=dtype)
    r = np.zeros(x.shape, dtype=dtype)
    data = (i0, gx, gy, alpha, v0, vx, vy)
    nch = 4 * get_num_threads()
    energy, emax = irls_pass(x, *data, 1.0, False, *wts, invd, r, nch, prob.complete)
    history, inner = [energy], []
    for k in range(1, irls_iterations):
        # eps = 0 (pure IRLS) must not divide by an exactly-zero residual: floor it far below the
        # largest residual (of the iterate before x: the pass that reads x needs eps already)
        eps = max(eps0 * eps_decay ** (k - 1), 1e-12 * emax, 1e-300)
        # weights eps / (|e| + eps) lie in (0, 1]: any common scale gives the same correction
        # (A and r scale together), and this one needs no extra pass and cannot overflow float32
        energy, emax = irls_pass(x, *data, eps, True, *wts, invd, r, nch, prob.complete)
        if k > 1:
            history.append(energy)
        pre = Multigrid(*wts, dtype=dtype, sweeps=sweeps, invd0=invd)
        d, _, it = pcg_planar(r, *wts, pre, tol=tol, maxiter=cg_iterations, overwrite_b=True)
        x += d
        inner.append(it)
    if irls_iterations > 1:
        energy, _ = irls_pass(x, *data, 1.0, False, *wts, invd, r, nch, prob.complete)
        history.append(energy)
    return from_planar(x), history, inner
