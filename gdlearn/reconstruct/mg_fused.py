"""Fused passes of the multigrid V-cycle (:mod:`.multigrid`) on the split layout of :mod:`.split`:
several of :mod:`.mg_kernels`' stencils in one pass over a level, where each pass alone would
reread the same rows from memory (at 1280 x 720 x 3 the finest level's stencils run at memory
speed, ~25 GB/s on one core).

The fused passes stay parallel over rows without races by a halo: what a row needs from rows
that another thread writes, it recomputes privately from inputs no thread writes (b, the
weights, the prolonged z). Operator ``A = W0 + Dx^T Wx Dx + Dy^T Wy Dy`` (Eq. 18-19, weighted).
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from gdlearn.reconstruct._jit import kernel
from gdlearn.reconstruct.mg_kernels import _split_row, n_chunks
from gdlearn.reconstruct.split import half_count


@njit(cache=True, fastmath=True, inline="always")
def _presmooth_row(dst, dk, dy, b, invd, wx, wy, k, kw, y, om, w, t):
    """Row y of channel k after the first red sweep from z = 0 and the black sweep after it,
    into dst[dk, dy] (a row of z, or a private halo row): red z = om D^-1 b (the whole half: its
    frame slots get 0), black z = om D^-1 (b + the weighted red neighbours), the red values of
    rows y - 1 and y + 1 recomputed as om D^-1 b -- a function of b alone, so any thread can
    compute any row. t: a scratch row of Wh values. (Whole arrays and indices come in, the slices
    are made here: see :mod:`.mg_kernels` on loops in the kernel body.)"""
    zrow = dst[dk, dy]
    hr = y % 2                        # red ((X + Y) even) pixels of row y; black in 1 - hr
    hb = 1 - hr
    zr, br, idr = zrow[hr], b[k, y, hr], invd[kw, y, hr]
    for i in range(zr.shape[0]):
        zr[i] = om * br[i] * idr[i]
    q = hr                            # the black half's slices start at 1 - hb = hr
    rl, rr = zrow[q], zrow[q, 1:]
    bu, bd, idu, idd = b[k, y - 1, hb, q:], b[k, y + 1, hb, q:], invd[kw, y - 1, hb, q:], \
        invd[kw, y + 1, hb, q:]
    bs, ids, wxs, wxl = b[k, y, hb, q:], invd[kw, y, hb, q:], wx[kw, y, hb, q:], wx[kw, y, q]
    wys, wyu = wy[kw, y, hb, q:], wy[kw, y - 1, hb, q:]
    n = half_count(hb, w)
    # into the scratch row first: a loop storing into zrow while it reads zrow's red half stays
    # scalar
    for i in range(n):
        t[i] = om * (bs[i] + wxs[i] * rr[i] + wxl[i] * rl[i] + wys[i] * (om * bd[i] * idd[i])
                     + wyu[i] * (om * bu[i] * idu[i])) * ids[i]
    zs = zrow[hb, q:]
    for i in range(n):
        zs[i] = t[i]


@kernel(fastmath=True)
def rb_first_pair(z, b, wx, wy, invd, om, w):
    """The first red sweep from z = 0 and the black sweep after it, in one pass (rows
    independent, see :func:`_presmooth_row`; z written once instead of three times)."""
    c, hp, _, wh = z.shape
    cw = invd.shape[0]
    n = hp - 2
    nch = n_chunks(n, 8)
    for j in prange(nch):
        t = np.empty(wh, dtype=z.dtype)
        for y in range(1 + j * n // nch, 1 + (j + 1) * n // nch):
            for k in range(c):
                _presmooth_row(z, k, y, b, invd, wx, wy, k, k if cw > 1 else 0, y, om, w, t)


@njit(cache=True, fastmath=True, inline="always")
def _presmoothed_residual_row(res, f, z, halo, k, kw, y, up_halo, down_halo, b, invd, wx, wy,
                              om, w):
    """b - A z on row y into res[f] (2 x Wh), from the presmoothed rows y - 1 (halo[k, 0] if
    up_halo), y, y + 1 (halo[k, 1] if down_halo). After :func:`_presmooth_row` no diagonal
    product is needed: at red points D z = om b (0 where D = 0), so b - A z = (1 - om) b + the
    weighted (black) neighbours; at black points, with s = b + the weighted (red) neighbours,
    D z = om s, so b - A z = (1 - om) s."""
    zrow = z[k, y]
    zu = halo[k, 0] if up_halo else z[k, y - 1]
    zd = halo[k, 1] if down_halo else z[k, y + 1]
    rf = res[f]
    zero = om - om                    # 0 in the vectors' dtype (a float64 0.0 would widen)
    for h in range(2):                # h = y % 2: the red half, whose other half is black
        q = 1 - h
        out, bs, ids, nr, nl = rf[h, q:], b[k, y, h, q:], invd[kw, y, h, q:], zrow[q, 1:], zrow[q]
        nd, nu, wxs, wxl = zd[h, q:], zu[h, q:], wx[kw, y, h, q:], wx[kw, y, q]
        wys, wyu = wy[kw, y, h, q:], wy[kw, y - 1, h, q:]
        n = half_count(h, w)
        if h == y % 2:
            for i in range(n):
                bi = bs[i]
                dz = om * bi if ids[i] > zero else zero
                out[i] = (bi - dz) + wxs[i] * nr[i] + wxl[i] * nl[i] + wys[i] * nd[i] \
                    + wyu[i] * nu[i]
        else:
            for i in range(n):
                s = bs[i] + wxs[i] * nr[i] + wxl[i] * nl[i] + wys[i] * nd[i] + wyu[i] * nu[i]
                out[i] = s - (om * s if ids[i] > zero else zero)


@kernel(fastmath=True)
def presmooth_restrict(z, b, wx, wy, invd, om, rc, w):
    """One pre-smoothing sweep (red from z = 0, then black: :func:`rb_first_pair`) and
    rc = P^T (b - A z), in one pass over the level -- what the V-cycle does before its coarse
    correction with one sweep. The residual after that sweep needs no diagonal product (see the
    two residual helpers), and since the presmoothed z is a function of b alone, each chunk of
    coarse rows recomputes the rows just outside its fine rows privately (a halo) instead of
    reading rows other threads write: rows stay race-free. z is written on the chunk's own rows
    only; w0 is not needed."""
    nch = n_chunks(rc.shape[1], 16)   # halo: 2 fine rows per chunk, <= 1/16 more work
    for j in prange(nch):
        _presmooth_restrict_chunk(j, nch, z, b, wx, wy, invd, om, rc, w)


@njit(cache=True, fastmath=True)
def _presmooth_restrict_chunk(j, nch, z, b, wx, wy, invd, om, rc, w):
    """Chunk j of nch (coarse rows j hcp / nch ..) of :func:`presmooth_restrict`; a function
    of its own so that tests can run the chunks in any order."""
    c, hp, _, wh = z.shape
    cw = invd.shape[0]
    hcp, whc = rc.shape[1], rc.shape[3]
    wc = (w + 1) // 2
    c0, c1 = j * hcp // nch, (j + 1) * hcp // nch
    ys, ye = max(1, 2 * c0 - 1), min(hp - 2, 2 * c1 - 2)      # the chunk's fine rows
    halo = np.zeros((c, 2, 2, wh), dtype=z.dtype)     # rows ys - 1, ye + 1 (0: the frame)
    t = np.empty(wh, dtype=z.dtype)
    res = np.zeros((2, 2, wh), dtype=rc.dtype)         # slots never written stay 0
    tmp = np.zeros(2 * whc, dtype=rc.dtype)            # tmp[0], tmp[wc + 1:] stay 0
    for k in range(c):
        kw = k if cw > 1 else 0
        if ys > ye:                 # a chunk of frame coarse rows only: no halo
            break
        if ys - 1 >= 1:
            _presmooth_row(halo, k, 0, b, invd, wx, wy, k, kw, ys - 1, om, w, t)
        if ye + 1 <= hp - 2:
            _presmooth_row(halo, k, 1, b, invd, wx, wy, k, kw, ye + 1, om, w, t)
    done = ys - 1                                       # own rows presmoothed so far
    for yc in range(c0, c1):
        if yc == 0 or yc == hcp - 1:
            for k in range(c):
                rc[k, yc] = 0.0
            continue
        while done < min(2 * yc + 1, ye):              # rows 2 yc - 1 .. 2 yc + 1
            done += 1
            for k in range(c):
                _presmooth_row(z, k, done, b, invd, wx, wy, k, k if cw > 1 else 0, done, om, w,
                               t)
        for k in range(c):
            kw = k if cw > 1 else 0
            for f in range(2):
                y = 2 * yc - 1 + f
                if y > hp - 2:          # odd height: the last coarse row has one fine row
                    res[f] = 0.0
                    continue
                _presmoothed_residual_row(res, f, z, halo, k, kw, y, y - 1 == ys - 1,
                                          y + 1 == ye + 1, b, invd, wx, wy, om, w)
            r0o, r0e, r1o, r1e, t1 = res[0, 1], res[0, 0, 1:], res[1, 1], res[1, 0, 1:], tmp[1:]
            for i in range(wc):
                t1[i] = r0o[i] + r0e[i] + r1o[i] + r1e[i]
            _split_row(tmp, rc[k, yc])
