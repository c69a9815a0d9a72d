"""The stencils of the multigrid V-cycle (:mod:`.multigrid`) on the split layout of :mod:`.split`:
smoothers (red-black SOR, damped Jacobi), residual + restriction, prolongation, coarsening and
the inverse diagonal of ``A = W0 + Dx^T Wx Dx + Dy^T Wy Dy`` (Eq. 18-19, weighted form). Passes
that fuse several of them: :mod:`.mg_fused`.

**Loops in the kernel body.** A half row's loop is written where its slices are made, not in a
helper called with them: such a call costs ~0.1 us in a serial twin (each slice's reference
count is updated around it) -- more than the work of a coarse level's short row (a sweep at
64 x 64 x 3 took 25 us with helpers, 5 us without; at 1280 x 720 the same).

Every kernel takes the level's interior width ``w`` and writes interior values only (the frame of
vectors and weights stays 0, see :mod:`.split`). Transfers between a level and the next coarser one
go through a natural-order coarse row buffer: coarse column Xc covers fine columns 2 Xc - 1 (odd
half, index Xc - 1) and 2 Xc (even half, index Xc), so a coarse row is ``odd[i] + even[1 + i]``
for i < Wc in the fine halves -- two contiguous slices -- and is then split into its own halves.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from gdlearn.reconstruct._jit import kernel
from gdlearn.reconstruct.split import half_count

#: Row-parallel kernels that need a row buffer split the rows into at most this many chunks and
#: make one buffer per chunk (made per row, the allocations cost ~10 % of a sweep at 1280 x 720).
CHUNKS = 16


@njit(cache=True)
def n_chunks(rows, per_chunk):
    """Chunks of a row-parallel kernel over ``rows`` rows: at most CHUNKS, each of at least
    ``per_chunk`` rows -- a chunk pays for its buffers and, in the fused passes, for its halo
    rows (16 chunks of a 32-row coarse level doubled the work of presmooth_restrict)."""
    return max(1, min(CHUNKS, rows // per_chunk))


@kernel(fastmath=True)
def rb_sweep(z, b, wx, wy, invd, colour, om, w):
    """SOR (``om`` x the Gauss-Seidel step; om = 1: Gauss-Seidel), in place, on the pixels with
    (X + Y) % 2 == colour -- half ``(colour + Y) % 2`` of row Y. Their four neighbours have the
    other colour, so rows are independent (parallel) and the order does not matter. ``om`` has
    the vectors' dtype (a float64 scalar would widen a float32 loop to float64)."""
    c, hp, _, wh = z.shape
    cw = wx.shape[0]
    n = hp - 2
    nch = n_chunks(n, 8)
    for j in prange(nch):
        t = np.empty(wh, dtype=z.dtype)
        for y in range(1 + j * n // nch, 1 + (j + 1) * n // nch):
            h = (colour + y) % 2
            q = 1 - h
            m = half_count(h, w)
            for k in range(c):
                kw = k if cw > 1 else 0
                zs, zl, zr, zu, zd = (z[k, y, h, q:], z[k, y, q], z[k, y, q, 1:],
                                      z[k, y - 1, h, q:], z[k, y + 1, h, q:])
                bs, ids, wxs = b[k, y, h, q:], invd[kw, y, h, q:], wx[kw, y, h, q:]
                wxl, wys, wyu = wx[kw, y, q], wy[kw, y, h, q:], wy[kw, y - 1, h, q:]
                # the Gauss-Seidel values into a private buffer first: a loop that stores into z
                # while it reads z's other half and rows stays scalar
                for i in range(m):
                    t[i] = (bs[i] + wxs[i] * zr[i] + wxl[i] * zl[i] + wys[i] * zd[i]
                            + wyu[i] * zu[i]) * ids[i]
                for i in range(m):
                    zs[i] += om * (t[i] - zs[i])


@kernel(fastmath=True)
def jacobi(z, b, w0, wx, wy, invd, omega, out, w):
    """One damped Jacobi sweep: out = z + omega D^-1 (b - A z) on the interior."""
    c, hp = z.shape[0], z.shape[1]
    cw = w0.shape[0]
    for y in prange(1, hp - 1):
        for k in range(c):
            kw = k if cw > 1 else 0
            for h in range(2):
                q = 1 - h
                zs, zl, zr, zu, zd = (z[k, y, h, q:], z[k, y, q], z[k, y, q, 1:],
                                      z[k, y - 1, h, q:], z[k, y + 1, h, q:])
                bs, w0s, wxs, wxl = b[k, y, h, q:], w0[kw, y, h, q:], wx[kw, y, h, q:], wx[kw, y, q]
                wys, wyu, ids, os = (wy[kw, y, h, q:], wy[kw, y - 1, h, q:], invd[kw, y, h, q:],
                                     out[k, y, h, q:])
                for i in range(half_count(h, w)):
                    pc = zs[i]
                    v = (w0s[i] * pc + wxs[i] * (pc - zr[i]) + wxl[i] * (pc - zl[i])
                         + wys[i] * (pc - zd[i]) + wyu[i] * (pc - zu[i]))
                    os[i] = pc + omega * ids[i] * (bs[i] - v)


@kernel(fastmath=True)
def scaled(b, invd, omega, out):
    """The first Jacobi sweep from z = 0: out = omega D^-1 b (the frame gets 0)."""
    c, hp, _, wh = b.shape
    cw = invd.shape[0]
    for y in prange(hp):
        for k in range(c):
            kw = k if cw > 1 else 0
            for h in range(2):
                br, idr, outr = b[k, y, h], invd[kw, y, h], out[k, y, h]
                for i in range(wh):
                    outr[i] = omega * idr[i] * br[i]


@njit(cache=True)
def _split_row(t, out):
    """Natural-order coarse row t -> its two halves out[0], out[1]."""
    for j in range(out.shape[1]):
        out[0, j] = t[2 * j]
        out[1, j] = t[2 * j + 1]


@kernel(fastmath=True)
def residual_restrict(z, b, w0, wx, wy, rc, w):
    """rc = P^T (b - A z): the residual summed over 2 x 2 blocks, one coarse row at a time."""
    c, hp, _, wh = z.shape
    cw = w0.shape[0]
    hcp, whc = rc.shape[1], rc.shape[3]
    wc = (w + 1) // 2
    nch = n_chunks(hcp, 4)
    for j in prange(nch):
        res = np.zeros((2, wh), dtype=rc.dtype)      # slots never written stay 0 (frame)
        tmp = np.zeros(2 * whc, dtype=rc.dtype)
        for yc in range(j * hcp // nch, (j + 1) * hcp // nch):
            for k in range(c):
                if yc == 0 or yc == hcp - 1:
                    rc[k, yc] = 0.0
                    continue
                kw = k if cw > 1 else 0
                tmp[:] = 0.0
                for y in range(2 * yc - 1, min(2 * yc + 1, hp - 1)):
                    for h in range(2):
                        q = 1 - h
                        zs, zl, zr = z[k, y, h, q:], z[k, y, q], z[k, y, q, 1:]
                        zu, zd, bs = z[k, y - 1, h, q:], z[k, y + 1, h, q:], b[k, y, h, q:]
                        rs = res[h, q:]
                        w0s, wxs, wxl = w0[kw, y, h, q:], wx[kw, y, h, q:], wx[kw, y, q]
                        wys, wyu = wy[kw, y, h, q:], wy[kw, y - 1, h, q:]
                        for i in range(half_count(h, w)):
                            pc = zs[i]
                            rs[i] = bs[i] - (w0s[i] * pc + wxs[i] * (pc - zr[i])
                                             + wxl[i] * (pc - zl[i]) + wys[i] * (pc - zd[i])
                                             + wyu[i] * (pc - zu[i]))
                    r1, r0 = res[1], res[0, 1:]
                    for i in range(wc):
                        tmp[1 + i] += r1[i] + r0[i]
                _split_row(tmp, rc[k, yc])


@kernel
def prolong_add(z, ec, w):
    """z += P ec on the interior: fine even column 2 + 2 i and odd column 1 + 2 i both lie in coarse
    column 1 + i."""
    c, hp = z.shape[0], z.shape[1]
    whc = ec.shape[3]
    n = hp - 2
    nch = n_chunks(n, 8)
    for j in prange(nch):
        t = np.empty(2 * whc, dtype=ec.dtype)
        for y in range(1 + j * n // nch, 1 + (j + 1) * n // nch):
            for k in range(c):
                er = ec[k, (y + 1) // 2]
                for i in range(whc):
                    t[2 * i] = er[0, i]
                    t[2 * i + 1] = er[1, i]
                for h in range(2):
                    zs, ts = z[k, y, h, 1 - h:], t[1:]
                    for i in range(half_count(h, w)):
                        zs[i] += ts[i]


@kernel
def coarsen(w0, wx, wy, factor, c0, cx, cy, w):
    """Coarse weights (split layout): block sums of w0; a coarse edge = factor x the two fine edges
    it crosses (see :mod:`.multigrid`). Fine values past the interior are the zero frame."""
    cw, hcp, _, whc = c0.shape
    wc = (w + 1) // 2
    nch = n_chunks(hcp, 4)
    for j in prange(nch):
        t = np.zeros(2 * whc, dtype=c0.dtype)        # t[0] and t[wc + 1:] stay 0 (frame)
        for yc in range(j * hcp // nch, (j + 1) * hcp // nch):
            for k in range(cw):
                if yc == 0 or yc == hcp - 1:
                    c0[k, yc] = 0.0
                    cx[k, yc] = 0.0
                    cy[k, yc] = 0.0
                    continue
                y = 2 * yc - 1
                for i in range(wc):
                    t[1 + i] = (w0[k, y, 1, i] + w0[k, y, 0, 1 + i] + w0[k, y + 1, 1, i]
                                + w0[k, y + 1, 0, 1 + i])
                _split_row(t, c0[k, yc])
                for i in range(wc):
                    t[1 + i] = factor * (wx[k, y, 0, 1 + i] + wx[k, y + 1, 0, 1 + i])
                _split_row(t, cx[k, yc])
                for i in range(wc):
                    t[1 + i] = factor * (wy[k, y + 1, 1, i] + wy[k, y + 1, 0, 1 + i])
                _split_row(t, cy[k, yc])


@kernel
def inverse_diagonal(w0, wx, wy, out, w):
    """1 / diag(A) where the diagonal is > 0, else 0 (a pixel with no term is in A's null space);
    interior only (``out`` must come zeroed)."""
    cw, hp = w0.shape[0], w0.shape[1]
    for y in prange(1, hp - 1):
        for k in range(cw):
            for h in range(2):
                q = 1 - h
                w0s, wxs, wxl = w0[k, y, h, q:], wx[k, y, h, q:], wx[k, y, q]
                wys, wyu, outs = wy[k, y, h, q:], wy[k, y - 1, h, q:], out[k, y, h, q:]
                for i in range(half_count(h, w)):
                    d = w0s[i] + wxs[i] + wxl[i] + wys[i] + wyu[i]
                    outs[i] = 1.0 / d if d > 0.0 else 0.0
