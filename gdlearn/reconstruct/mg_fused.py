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

from ._jit import kernel
from .mg_kernels import CHUNKS, _split_row
from .split import half_count


@njit(cache=True, fastmath=True)
def _first_black_half(zs, zl, zr, bu, bd, idu, idd, bs, wxs, wxl, wys, wyu, ids, om, n):
    """The black half row of :func:`rb_first_pair`: red neighbours left / right from z (this
    row's red half, just written), above / below recomputed as om D^-1 b."""
    for i in range(n):
        t = (bs[i] + wxs[i] * zr[i] + wxl[i] * zl[i] + wys[i] * (om * bd[i] * idd[i])
             + wyu[i] * (om * bu[i] * idu[i])) * ids[i]
        zs[i] = om * t


@njit(cache=True, fastmath=True)
def _presmooth_row(zrow, b, invd, wx, wy, k, kw, y, om, w):
    """Row y of channel k after the first red sweep from z = 0 and the black sweep after it,
    into zrow (2 x Wh: z[k, y] or a private buffer): red z = om D^-1 b (the whole half: its frame
    slots get 0), black z = om D^-1 (b + the weighted red neighbours), the red values of rows
    y - 1 and y + 1 recomputed as om D^-1 b -- a function of b alone, so any thread can compute
    any row."""
    hr = y % 2                        # red ((X + Y) even) pixels of row y; black in 1 - hr
    hb = 1 - hr
    zr, br, idr = zrow[hr], b[k, y, hr], invd[kw, y, hr]
    for i in range(zr.shape[0]):
        zr[i] = om * br[i] * idr[i]
    q = hr                            # the black half's slices start at 1 - hb = hr
    _first_black_half(zrow[hb, q:], zrow[q], zrow[q, 1:], b[k, y - 1, hb, q:], b[k, y + 1, hb, q:],
                      invd[kw, y - 1, hb, q:], invd[kw, y + 1, hb, q:], b[k, y, hb, q:],
                      wx[kw, y, hb, q:], wx[kw, y, q], wy[kw, y, hb, q:], wy[kw, y - 1, hb, q:],
                      invd[kw, y, hb, q:], om, half_count(hb, w))


@kernel(fastmath=True)
def rb_first_pair(z, b, wx, wy, invd, om, w):
    """The first red sweep from z = 0 and the black sweep after it, in one pass (rows
    independent, see :func:`_presmooth_row`; z written once instead of three times)."""
    c, hp = z.shape[0], z.shape[1]
    cw = invd.shape[0]
    for y in prange(1, hp - 1):
        for k in range(c):
            _presmooth_row(z[k, y], b, invd, wx, wy, k, k if cw > 1 else 0, y, om, w)


@njit(cache=True, fastmath=True)
def _presmoothed_residual_red(out, bs, ids, zr, zl, zd, zu, wxs, wxl, wys, wyu, om, n):
    """b - A z at red points after :func:`_presmooth_row`: D z = om b there (0 where D = 0), so
    the residual is (1 - om) b + the weighted (black) neighbours -- no diagonal product."""
    zero = om - om                    # 0 in the vectors' dtype (a float64 0.0 would widen)
    for i in range(n):
        bi = bs[i]
        dz = om * bi if ids[i] > zero else zero
        out[i] = (bi - dz) + wxs[i] * zr[i] + wxl[i] * zl[i] + wys[i] * zd[i] + wyu[i] * zu[i]


@njit(cache=True, fastmath=True)
def _presmoothed_residual_black(out, bs, ids, zr, zl, zd, zu, wxs, wxl, wys, wyu, om, n):
    """b - A z at black points after :func:`_presmooth_row`: with s = b + the weighted (red)
    neighbours, D z = om s (0 where D = 0), so the residual is (1 - om) s."""
    zero = om - om
    for i in range(n):
        t = bs[i] + wxs[i] * zr[i] + wxl[i] * zl[i] + wys[i] * zd[i] + wyu[i] * zu[i]
        out[i] = t - (om * t if ids[i] > zero else zero)


@njit(cache=True, fastmath=True)
def _presmoothed_residual_row(res, zrow, zu, zd, b, invd, wx, wy, k, kw, y, om, w):
    """b - A z on row y (into res, 2 x Wh) from the presmoothed rows y - 1, y, y + 1."""
    hr = y % 2
    hb = 1 - hr
    q = hb                            # red half: slices from 1 - hr; its other half is hb
    _presmoothed_residual_red(res[hr, q:], b[k, y, hr, q:], invd[kw, y, hr, q:], zrow[q, 1:],
                              zrow[q], zd[hr, q:], zu[hr, q:], wx[kw, y, hr, q:], wx[kw, y, q],
                              wy[kw, y, hr, q:], wy[kw, y - 1, hr, q:], om, half_count(hr, w))
    q = hr                            # black half: slices from 1 - hb; its other half is hr
    _presmoothed_residual_black(res[hb, q:], b[k, y, hb, q:], invd[kw, y, hb, q:], zrow[q, 1:],
                                zrow[q], zd[hb, q:], zu[hb, q:], wx[kw, y, hb, q:], wx[kw, y, q],
                                wy[kw, y, hb, q:], wy[kw, y - 1, hb, q:], om, half_count(hb, w))


@kernel(fastmath=True)
def presmooth_restrict(z, b, wx, wy, invd, om, rc, w):
    """One pre-smoothing sweep (red from z = 0, then black: :func:`rb_first_pair`) and
    rc = P^T (b - A z), in one pass over the level -- what the V-cycle does before its coarse
    correction with one sweep. The residual after that sweep needs no diagonal product (see the
    two residual helpers), and since the presmoothed z is a function of b alone, each chunk of
    coarse rows recomputes the rows just outside its fine rows privately (a halo) instead of
    reading rows other threads write: rows stay race-free. z is written on the chunk's own rows
    only; w0 is not needed."""
    nch = min(CHUNKS, rc.shape[1])
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
    res = np.zeros((2, 2, wh), dtype=rc.dtype)         # slots never written stay 0
    tmp = np.zeros(2 * whc, dtype=rc.dtype)            # tmp[0], tmp[wc + 1:] stay 0
    for k in range(c):
        kw = k if cw > 1 else 0
        if ys > ye:                 # a chunk of frame coarse rows only: no halo
            break
        if ys - 1 >= 1:
            _presmooth_row(halo[k, 0], b, invd, wx, wy, k, kw, ys - 1, om, w)
        if ye + 1 <= hp - 2:
            _presmooth_row(halo[k, 1], b, invd, wx, wy, k, kw, ye + 1, om, w)
    done = ys - 1                                       # own rows presmoothed so far
    for yc in range(c0, c1):
        if yc == 0 or yc == hcp - 1:
            for k in range(c):
                rc[k, yc] = 0.0
            continue
        while done < min(2 * yc + 1, ye):              # rows 2 yc - 1 .. 2 yc + 1
            done += 1
            for k in range(c):
                _presmooth_row(z[k, done], b, invd, wx, wy, k, k if cw > 1 else 0, done,
                               om, w)
        for k in range(c):
            kw = k if cw > 1 else 0
            for f in range(2):
                y = 2 * yc - 1 + f
                if y > hp - 2:          # odd height: the last coarse row has one fine row
                    res[f] = 0.0
                    continue
                zu = halo[k, 0] if y - 1 == ys - 1 else z[k, y - 1]
                zd = halo[k, 1] if y + 1 == ye + 1 else z[k, y + 1]
                _presmoothed_residual_row(res[f], z[k, y], zu, zd, b, invd, wx, wy, k, kw,
                                          y, om, w)
            r0o, r0e, r1o, r1e, t1 = res[0, 1], res[0, 0, 1:], res[1, 1], res[1, 0, 1:], tmp[1:]
            for i in range(wc):
                t1[i] = r0o[i] + r0e[i] + r1o[i] + r1e[i]
            _split_row(tmp, rc[k, yc])
