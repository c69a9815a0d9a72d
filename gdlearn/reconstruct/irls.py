"""L1 reconstruction by IRLS with a multigrid-preconditioned inner solve (the default path of
:func:`gdlearn.reconstruct.poisson_l1`).

Energy (Eq. 18 with n = 1, the reference solver's convention, see :mod:`.poisson`)::

    E(I) = sum_p alpha |I_p - I0_p| + |(Dx I - Gx)_p| + |(Dy I - Gy)_p|

Reweighting k (the reference solver's L1D preset): term weights ``q = 1 / (|e| + eps_k)`` from the
current residual lengths ``e`` (the reference normalises them to mean 1; any common factor gives
the same step, here they are scaled by eps_k into (0, 1]), then one weighted least-squares step.
How that step is solved is what makes this path fast:

* **One pass per reweighting** (:func:`irls_pass`): residual lengths, L1 energy, weights, the
  operator's inverse diagonal, the residual below and its norm come from one sweep over the data
  (previously five passes: lengths, weight sum, weights, residual, diagonal); the L2 start needs
  no pass of its own (the first reweighting's pass measures its energy).
* **Correction form.** The float64 residual of the reweighted normal equations
  ``r = b - A x = W0 (I0 - x) - Dx^T Wx (Dx x - Gx) - Dy^T Wy (Dy x - Gy)`` comes from one stencil
  pass over the data; only the correction ``A d = r`` is solved, in float32 (half the memory
  traffic), its CG steps added straight to the float64 x. The next reweighting recomputes the
  residual in float64, so float32 round-off in ``d`` is corrected as in iterative refinement.
* **Shared weights.** The reference solver reweights a pixel's RGB residual as one vector, so on
  complete data the channels share one weight per term: weights are 1 x H x W (a third of the
  memory). Missing (non-finite) input makes them per channel (weight 0 where missing).
* **Multigrid preconditioner** (:class:`.multigrid.Multigrid`) built on the actual weights, which
  span up to ``1 / eps`` (1e7 by the last reweighting) -- where the DCT solve of the mean weight
  needs tens of CG steps, the V-cycle needs a few; one symmetric-SOR sweep (omega 1.2) before
  and after each coarse correction, the pre-sweep fused with the residual and restriction. Each
  reweighting's Multigrid and CG reuse the previous one's arrays (no fresh pages).
* **Stopping rule per reweighting**: CG stops when the correction's residual has dropped by
  ``tol`` relative to its start (not relative to ``b``: the start of a warm-started reweighting
  is already close, and a tolerance relative to ``b`` stops after zero steps once eps is small).

All of it runs on the red-black split layout of :mod:`.split` (each padded row stored as its even
then its odd columns), where every stencil reads contiguous half rows and the smoother computes
only the colour it moves. Where the time goes at 1280 x 720 x 3: ``benchmarks/README.md`` (bench_reconstruct).
"""
from __future__ import annotations

import numpy as np
from numba import get_num_threads, njit, prange

from gdlearn.reconstruct._jit import kernel
from gdlearn.reconstruct.multigrid import Multigrid
from gdlearn.reconstruct.planar import pcg_planar
from gdlearn.reconstruct.split import from_split, half_count, split_operator, split_shape, to_split

__all__ = ["irls_multigrid"]


@kernel(fastmath=True, error_model="numpy")
def irls_pass(img, i0, gx, gy, alpha, v0, vx, vy, eps, full, w0, wx, wy, invd, r, nch,
              complete, w):
    """One sweep over the data from the current iterate ``img`` (split layout float64, interior
    width w): the L1 energy (Eq. 18, n = 1) and the largest residual length; with ``full``, also
    the IRLS weights of the next reweighting ``q = eps / (|e| + eps) = 1 / (1 + |e| / eps)`` times
    validity (alpha^2 on w0), the inverse diagonal of the reweighted operator (0 where it is 0)
    and the residual of its normal equations
    ``r = W0 (I0 - x) - Dx^T Wx (Dx x - Gx) - Dy^T Wy (Dy x - Gy)`` computed in float64 (the outer
    residual of the iterative refinement, see the module docstring).

    The weights are the reference's ``1 / (|e| + eps)`` times eps: any common factor leaves the
    correction unchanged (A and r scale together), and this one puts them in (0, 1] without the
    extra pass a normalisation to mean 1 needs and without any risk of float32 overflow.

    Each row is read once (``nch`` chunks of rows, each with its own row buffers). Row y needs
    the weight of the edge above it, (y-1)-(y), which row y-1 writes: at a chunk's start it is
    recomputed from the same data instead (rows are independent, so the loop stays parallel).
    ``complete``: v0, vx, vy are 1 x 2 x 2 x Wh -- row 1 the validity of every interior row, row
    0 zeros (the masked last row of gy, the frame above the first) -- instead of full arrays
    (see :func:`split_problem`). Outputs are written on the interior only: their frames must be 0
    (they are allocated zeroed once). Returns (energy, largest length, r^T r per channel -- 0
    without ``full``)."""
    c, hp, _, wh = img.shape
    rows = np.zeros((hp, 2))
    rr = np.zeros((hp, c))
    # row buffers are made once per chunk of rows (nch chunks): made per row they cost as much
    # as the sweep
    nch = max(1, min(nch, (hp - 2) // 16))   # each chunk's first row also computes eu
    for j in prange(nch):
        lens = np.zeros((4, 2, wh))        # lengths e0, ex, ey and eu (the edge above)
        q = np.zeros((4, 2, wh), dtype=np.float32)     # their weights
        start = 1 + j * (hp - 2) // nch
        for y in range(start, 1 + (j + 1) * (hp - 2) // nch):
            # the edge above row y is row y-1's edge below: computed only at a chunk's start
            rows[y, 0], rows[y, 1] = _lengths_row(y, img, i0, gx, gy, alpha, v0, vx, vy,
                                                  lens, full and y == start, complete, w)
            if full:
                _weights_row(y, i0, img, gx, gy, lens, q, alpha * alpha, eps, v0, vx, vy,
                             w0, wx, wy, invd, r, complete, w, rr[y])
                lens[3] = lens[2]
    return rows[:, 0].sum(), rows[:, 1].max(), rr.sum(axis=0)


@njit(cache=True)
def _validity_rows(y, hp, complete):
    """Rows of v0, vx, vy (row y) and vy (row y - 1) that hold row y's validity."""
    if complete:
        return 1, 1, 1 if y < hp - 2 else 0, 1 if y > 1 else 0
    return y, y, y, y - 1


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _squares_half(e0, ex, ey, ic, ir, idn, i0s, gxs, gys, v0s, vxs, vys, alpha, n):
    """Add one channel's squared residuals (times validity) of one half row to e0, ex, ey."""
    for i in range(n):
        c = ic[i]
        d0 = alpha * (c - i0s[i])
        ddx = ir[i] - c - gxs[i]
        ddy = idn[i] - c - gys[i]
        e0[i] += v0s[i] * d0 * d0
        ex[i] += vxs[i] * ddx * ddx
        ey[i] += vys[i] * ddy * ddy


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _squares_complete(e0, ex, ey, ic, ir, idn, i0s, gxs, gys, alpha, n):
    """_squares_half for complete data (validity 1; the caller zeroes the masked terms)."""
    for i in range(n):
        c = ic[i]
        d0 = alpha * (c - i0s[i])
        ddx = ir[i] - c - gxs[i]
        ddy = idn[i] - c - gys[i]
        e0[i] += d0 * d0
        ex[i] += ddx * ddx
        ey[i] += ddy * ddy


@njit(cache=True, fastmath=True, error_model="numpy")
def _lengths_row(y, img, i0, gx, gy, alpha, v0, vx, vy, lens, with_eu, complete, w):
    """Row y of irls_pass: colour lengths of the residuals into lens (e0, ex, ey; with
    ``with_eu`` also eu, the edge above (y-1, x) - (y, x), else lens[3] must hold row y-1's ey
    already); returns (sum of the row's e0, ex, ey, largest)."""
    c, hp = img.shape[0], img.shape[1]
    cv = v0.shape[0]
    r0, rx, ry, ru = _validity_rows(y, hp, complete)
    tot = 0.0
    big = 0.0
    for h in range(2):
        q = 1 - h
        n = half_count(h, w)
        e0, ex, ey, eu = lens[0, h, q:], lens[1, h, q:], lens[2, h, q:], lens[3, h, q:]
        e0[:n] = 0.0
        ex[:n] = 0.0
        ey[:n] = 0.0
        if with_eu:
            eu[:n] = 0.0
        for k in range(c):
            kv = k if cv > 1 else 0
            ic, gyu, vu = img[k, y, h, q:], gy[k, y - 1, h, q:], vy[kv, ru, h, q:]
            if complete:
                _squares_complete(e0, ex, ey, ic, img[k, y, q, 1:], img[k, y + 1, h, q:],
                                  i0[k, y, h, q:], gx[k, y, h, q:], gy[k, y, h, q:], alpha, n)
            else:
                _squares_half(e0, ex, ey, ic, img[k, y, q, 1:], img[k, y + 1, h, q:],
                              i0[k, y, h, q:], gx[k, y, h, q:], gy[k, y, h, q:],
                              v0[kv, r0, h, q:], vx[kv, rx, h, q:], vy[kv, ry, h, q:], alpha, n)
            if with_eu:
                iu = img[k, y - 1, h, q:]
                for i in range(n):
                    ddu = ic[i] - iu[i] - gyu[i]
                    eu[i] += vu[i] * ddu * ddu
        if complete:
            # validity is 1 but for the masked last column of gx and last row of gy: zeroed
            # here instead of loaded per channel and value (a third fewer loads)
            if h == w % 2:
                ex[w // 2 - q] = 0.0
            if y == hp - 2:
                ey[:n] = 0.0
        for i in range(n):
            e0[i] = np.sqrt(e0[i])
        for i in range(n):
            ex[i] = np.sqrt(ex[i])
        for i in range(n):
            ey[i] = np.sqrt(ey[i])
        if with_eu:
            for i in range(n):
                eu[i] = np.sqrt(eu[i])
        for i in range(n):
            tot += e0[i] + ex[i] + ey[i]
            big = max(big, max(e0[i], max(ex[i], ey[i])))
    return tot, big


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _q_half(out, e, v, scale, ie, n):
    """IRLS weights scale v / (1 + e / eps) of one half row, in float32: twice the SIMD width of
    float64 divisions, and 1 + e / eps >= 1 cannot divide by 0 whatever eps is."""
    one = np.float32(1.0)
    for i in range(n):
        out[i] = scale * np.float32(v[i]) / (one + np.float32(e[i] * ie))


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _residual_half(rs, i0s, ic, il, ir, iu, idn, gxs, gxl, gys, gyu, q0, qxs, qxl, qys, qyu, n):
    """r = W0 (I0 - x) - Dx^T Wx (Dx x - Gx) - Dy^T Wy (Dy x - Gy) on one half row (float64
    arithmetic; the data rows are cache-resident, cheaper to reread than to store residuals);
    returns its sum of squares."""
    s = 0.0
    for i in range(n):
        c = ic[i]
        v = (q0[i] * (i0s[i] - c) + qxs[i] * (ir[i] - c - gxs[i])
             - qxl[i] * (c - il[i] - gxl[i]) + qys[i] * (idn[i] - c - gys[i])
             - qyu[i] * (c - iu[i] - gyu[i]))
        rs[i] = v
        s += v * v
    return s


@njit(cache=True, fastmath=True, error_model="numpy")
def _weights_row(y, i0, img, gx, gy, lens, q, a2, eps, v0, vx, vy, w0, wx, wy, invd, r,
                 complete, w, rr):
    """Row y of irls_pass's weights ``1 / (1 + |e| / eps)``, inverse diagonal and residual (its
    sum of squares per channel into rr), from the lengths (e0, ex, ey, eu in lens); q: a float32
    4 x 2 x Wh buffer whose frame slot q[1, 0, 0] (the edge left of the first pixel) is 0."""
    c, hp = img.shape[0], img.shape[1]
    cv = v0.shape[0]
    r0, rx, ry, ru = _validity_rows(y, hp, complete)
    ie = 1.0 / eps
    one = np.float32(1.0)
    a2f = np.float32(a2)
    for kw in range(cv):
        for h in range(2):
            s = 1 - h
            n = half_count(h, w)
            _q_half(q[0, h, s:], lens[0, h, s:], v0[kw, r0, h, s:], a2f, ie, n)
            _q_half(q[1, h, s:], lens[1, h, s:], vx[kw, rx, h, s:], one, ie, n)
            _q_half(q[2, h, s:], lens[2, h, s:], vy[kw, ry, h, s:], one, ie, n)
            _q_half(q[3, h, s:], lens[3, h, s:], vy[kw, ru, h, s:], one, ie, n)
            w0[kw, y, h, s:s + n] = q[0, h, s:s + n]
            wx[kw, y, h, s:s + n] = q[1, h, s:s + n]
            wy[kw, y, h, s:s + n] = q[2, h, s:s + n]
        for h in range(2):
            s = 1 - h
            q0, qxs, qxl, qys, qyu = q[0, h, s:], q[1, h, s:], q[1, s], q[2, h, s:], q[3, h, s:]
            idr = invd[kw, y, h, s:]
            for i in range(half_count(h, w)):
                dg = q0[i] + qxs[i] + qxl[i] + qys[i] + qyu[i]
                idr[i] = one / dg if dg > 0.0 else 0.0
        for k in range(kw if cv > 1 else 0, kw + 1 if cv > 1 else c):
            for h in range(2):
                s = 1 - h
                rr[k] += _residual_half(r[k, y, h, s:], i0[k, y, h, s:], img[k, y, h, s:], img[k, y, s],
                               img[k, y, s, 1:], img[k, y - 1, h, s:], img[k, y + 1, h, s:],
                               gx[k, y, h, s:], gx[k, y, s], gy[k, y, h, s:], gy[k, y - 1, h, s:],
                               q[0, h, s:], q[1, h, s:], q[1, s], q[2, h, s:], q[3, h, s:],
                               half_count(h, w))


def split_problem(prob):
    """(i0, gx, gy, v0, vx, vy) in the split layout (float64): data with masked / missing entries
    0, and validity C x ... (per channel) -- or, for complete data, 1 x 2 x 2 x Wh: row 1 the
    validity every interior row shares (the masked last column of gx at 0), row 0 zeros."""
    h, w, c = prob.shape
    if not prob.complete:
        return tuple(to_split(a) for a in prob.clean())
    data = [to_split(a) for a in (prob.primal, prob.gx, prob.gy)]
    data[1][:, :, w % 2, w // 2] = 0.0      # the masked last column of gx may hold anything
    data[2][:, h] = 0.0                     # ... and the last row of gy
    inner = to_split(np.ones((1, w, 1)))[:, 1]      # 1 on the interior columns of a row
    valid = [np.zeros((1, 2) + inner.shape[1:]) for _ in range(3)]
    for v in valid:
        v[:, 1] = inner
    valid[1][:, 1, w % 2, w // 2] = 0.0
    return (*data, *valid)


def irls_multigrid(prob, x, alpha, irls_iterations, eps0, eps_decay, cg_iterations, tol,
                   dtype=np.float32, sweeps=1):
    """Reweightings 1 .. irls_iterations - 1 from the L2 start ``x`` (H x W x C float64);
    ``sweeps``: the V-cycle's smoothing sweeps (see :class:`.multigrid.Multigrid`).

    Returns (x H x W x C, L1 energy per outer iteration incl. the start, CG steps per reweighting).
    """
    h, w, c = prob.shape
    i0, gx, gy, v0, vx, vy = split_problem(prob)
    x = to_split(x)
    wshape = split_shape(1 if prob.complete else c, h, w)
    arrays = (tuple(np.zeros(wshape, dtype=dtype) for _ in range(3)),     # weights
              np.zeros(wshape, dtype=dtype), np.zeros(x.shape, dtype=dtype))   # invd, r
    data = (i0, gx, gy, alpha, v0, vx, vy)
    history, inner = _reweightings(x, data, arrays, prob.complete, w, irls_iterations, eps0,
                                   eps_decay, cg_iterations, tol, dtype, sweeps)
    return from_split(x, w), history, inner


def _reweightings(x, data, arrays, complete, w, irls_iterations, eps0, eps_decay, cg_iterations,
                  tol, dtype, sweeps):
    """The IRLS loop of :func:`irls_multigrid` on split-layout arrays (x updated in place)."""
    wts, invd, r = arrays
    op = split_operator(*wts, w)
    nch = 4 * get_num_threads()
    pre, work = None, {}         # the V-cycle's and CG's arrays, reused by every reweighting
    history, inner, emax = [], [], 0.0
    for k in range(1, irls_iterations):
        # eps = 0 (pure IRLS) must not divide by an exactly-zero residual: floor it far below the
        # largest residual (of the iterate before x: the pass that reads x needs eps already)
        eps = max(eps0 * eps_decay ** (k - 1), 1e-12 * emax, 1e-300)
        # weights eps / (|e| + eps) lie in (0, 1]: any common scale gives the same correction
        # (A and r scale together), and this one needs no extra pass and cannot overflow float32
        energy, emax_x, rr = irls_pass(x, *data, eps, True, *wts, invd, r, nch, complete, w)
        if k == 1 and 1e-12 * emax_x > eps:
            # the first floor needs the start's own largest residual, which a lengths-only pass
            # used to measure first: that pass is skipped and this one redone in the rare case
            # (residuals > 1e10 eps0) where the floor changes eps -- the same result either way
            eps = 1e-12 * emax_x
            energy, emax_x, rr = irls_pass(x, *data, eps, True, *wts, invd, r, nch, complete, w)
        history.append(energy)                 # the L1 energy of x before this reweighting
        emax = emax_x
        pre = Multigrid(*wts, w, dtype=dtype, sweeps=sweeps, invd0=invd, reuse=pre)
        # the float32 correction's steps go straight into the float64 iterate
        _, _, it = pcg_planar(r, op, pre, tol=tol, maxiter=cg_iterations, overwrite_b=True, x=x,
                              rr0=rr, work=work)
        inner.append(it)
    energy, _, _ = irls_pass(x, *data, 1.0, False, *wts, invd, r, nch, complete, w)
    history.append(energy)
    return history, inner
