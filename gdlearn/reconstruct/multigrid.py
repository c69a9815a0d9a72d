"""A multigrid V-cycle preconditioner for the weighted screened Poisson operator, on the padded
planar layout of :mod:`.planar` -- the inner solve of L1 by IRLS (Hua et al. 2019, Sec. 5.1):
the reweighting makes the weights span many decades, where a DCT solve of the mean-weight
operator is a poor preconditioner.

Operator (as in :mod:`.operators`): ``A = W0 + Dx^T Wx Dx + Dy^T Wy Dy``.

Layout: see :mod:`.planar` (padded C x (H+2) x (W+2) vectors, Cw x (H+2) x (W+2) weights with a
zero frame), so every stencil here runs without boundary tests.

**Coarsening** by aggregation: each 2 x 2 block is one coarse cell; prolongation P copies a coarse
value to its block, restriction is P^T (block sum). The coarse operator keeps the 5-point form:
``W0c = P^T W0 P`` (block sums) and a coarse edge weighs ``edge_factor`` times the sum of the two
fine edges it crosses. Galerkin (factor 1) is exactly P^T A P, but piecewise-constant P then
over-estimates the coarse Laplacian by 2 for smooth errors; factor 1/2 re-discretises it on the
coarse cells (cell-centred multigrid, Wesseling 1992, Ch. 5). The coarsest grid
(<= ``COARSEST_CELLS`` cells) is solved by a dense pseudo-inverse.

**Smoothers.** Red-black symmetric SOR (default): red then black before the coarse correction,
black then red after it -- the post-smoother is the adjoint of the pre-smoother -- each point
moved ``sor`` (default ``SOR_OMEGA = 1.2``) times its Gauss-Seidel update. Over-relaxation makes
one sweep worth more than two plain Gauss-Seidel sweeps here (see ``SOR_OMEGA``), so the IRLS
default is one sweep. Or damped Jacobi (``omega = 0.8``, symmetric, the same sweeps before and
after); per CG step it is cheaper but weaker (measured on the 320 x 180 benchmark problem: 2
Jacobi sweeps reach a worse L1 energy than 1 Gauss-Seidel sweep). Either smoother S satisfies
``S + S^T - A`` positive definite (for SOR it is ``(2 / sor - 1) D``), so the V-cycle ``B`` is
symmetric positive semi-definite, definite when A is -- what CG needs of a preconditioner
(tests/test_reconstruct_multigrid.py checks it, and that the eigenvalues of BA lie in (0, 2) up
to sor = 1.2: each cycle contracts the error).
"""
from __future__ import annotations

import numpy as np
from numba import prange

from ._jit import kernel
from .planar import apply_planar  # noqa: F401  (the operator the V-cycle approximates)

__all__ = ["Multigrid", "COARSE_EDGE_FACTOR", "COARSEST_CELLS", "OMEGA", "SOR_OMEGA"]

#: Coarse edge weight = this factor x (sum of the two fine edges it crosses); see the docstring.
COARSE_EDGE_FACTOR = 0.5
#: Stop coarsening at this many cells or fewer; that level is solved by a dense pseudo-inverse.
COARSEST_CELLS = 48
#: Jacobi damping: 0.8 is near the best smoothing factor of the 5-point Laplacian (4/5).
OMEGA = 0.8
#: Over-relaxation of the red-black Gauss-Seidel sweeps (symmetric SOR). Measured on the 320 x 180
#: problem of benchmarks/bench_reconstruct.py with one sweep: L1 energy / reference emulation
#: 1.00027 (omega 1, 28 CG steps), 0.99977 (1.2, 25), 0.99971 (1.3, 27), 0.99955 (1.5, 41 steps):
#: 1.2 with one sweep beats omega 1 with two sweeps (0.99983) at about half the smoothing work.
SOR_OMEGA = 1.2


@kernel(fastmath=True)
def _jacobi(z, b, w0, wx, wy, invd, omega, out):
    """One damped Jacobi sweep: out = z + omega D^-1 (b - A z) on the interior."""
    c, hp, wp = z.shape
    cw = w0.shape[0]
    for y in prange(1, hp - 1):
        for k in range(c):
            kw = k if cw > 1 else 0
            for x in range(1, wp - 1):
                pc = z[k, y, x]
                v = (w0[kw, y, x] * pc + wx[kw, y, x] * (pc - z[k, y, x + 1])
                     + wx[kw, y, x - 1] * (pc - z[k, y, x - 1])
                     + wy[kw, y, x] * (pc - z[k, y + 1, x])
                     + wy[kw, y - 1, x] * (pc - z[k, y - 1, x]))
                out[k, y, x] = pc + omega * invd[kw, y, x] * (b[k, y, x] - v)


#: Row-parallel kernels that need a row buffer split the rows into this many chunks and make one
#: buffer per chunk (made per row, the allocations cost ~10 % of a sweep at 1280 x 720).
CHUNKS = 16


@kernel(fastmath=True)
def _rb_sweep(z, b, w0, wx, wy, invd, colour, om):
    """SOR (``om`` x the Gauss-Seidel step; om = 1: Gauss-Seidel), in place, on the pixels with
    (x + y) % 2 == colour: their four neighbours
    have the other colour, so the rows are independent (parallel) and the result is the same in
    any order. The update is computed for the whole row into a buffer (a contiguous loop LLVM
    vectorises; twice the arithmetic, but a strided loop is no faster) and stored every 2nd.
    Rows are 1-D slices: simpler addressing, ~20 % faster than 3-D indexing."""
    c, hp, wp = z.shape
    cw = w0.shape[0]
    n = hp - 2
    nch = min(CHUNKS, n)
    for j in prange(nch):
        tmp = np.empty(wp, dtype=z.dtype)
        for y in range(1 + j * n // nch, 1 + (j + 1) * n // nch):
            for k in range(c):
                kw = k if cw > 1 else 0
                zr, zu, zd, br = z[k, y], z[k, y - 1], z[k, y + 1], b[k, y]
                wxr, wyr, wyu, idr = wx[kw, y], wy[kw, y], wy[kw, y - 1], invd[kw, y]
                for x in range(1, wp - 1):
                    tmp[x] = (br[x] + wxr[x] * zr[x + 1] + wxr[x - 1] * zr[x - 1]
                              + wyr[x] * zd[x] + wyu[x] * zu[x]) * idr[x]
                for x in range(1 + (y + 1 + colour) % 2, wp - 1, 2):
                    zr[x] += om * (tmp[x] - zr[x])


@kernel(fastmath=True)
def _rb_first(z, b, invd, om):
    """The first red sweep from z = 0: z = om D^-1 b on colour 0, 0 on colour 1 (interior only,
    so z needs no zeroing first)."""
    c, hp, wp = z.shape
    cw = invd.shape[0]
    for y in prange(1, hp - 1):
        for k in range(c):
            kw = k if cw > 1 else 0
            zr, br, idr = z[k, y], b[k, y], invd[kw, y]
            for x in range(1, wp - 1):
                zr[x] = om * br[x] * idr[x]
            for x in range(1 + y % 2, wp - 1, 2):   # colour 1: (x + y) odd
                zr[x] = 0.0


@kernel(fastmath=True)
def _scaled(b, invd, omega, out):
    """The first Jacobi sweep from z = 0: out = omega D^-1 b (frame stays 0)."""
    c, hp, wp = b.shape
    cw = invd.shape[0]
    for y in prange(hp):
        for k in range(c):
            kw = k if cw > 1 else 0
            for x in range(wp):
                out[k, y, x] = omega * invd[kw, y, x] * b[k, y, x]


@kernel(fastmath=True)
def _residual_restrict(z, b, w0, wx, wy, rc):
    """rc = P^T (b - A z): the residual summed over 2 x 2 blocks, one coarse row per iteration."""
    c, hp, wp = z.shape
    cw = w0.shape[0]
    hcp, wcp = rc.shape[1], rc.shape[2]
    for yc in prange(hcp):
        tmp = np.zeros(wp, dtype=rc.dtype)
        for k in range(c):
            kw = k if cw > 1 else 0
            rck = rc[k, yc]
            rck[:] = 0.0
            if yc == 0 or yc == hcp - 1:
                continue
            for y in range(2 * yc - 1, min(2 * yc + 1, hp - 1)):
                zr, zu, zd, br = z[k, y], z[k, y - 1], z[k, y + 1], b[k, y]
                w0r, wxr, wyr, wyu = w0[kw, y], wx[kw, y], wy[kw, y], wy[kw, y - 1]
                for x in range(1, wp - 1):
                    pc = zr[x]
                    tmp[x] = br[x] - (w0r[x] * pc + wxr[x] * (pc - zr[x + 1])
                                      + wxr[x - 1] * (pc - zr[x - 1]) + wyr[x] * (pc - zd[x])
                                      + wyu[x] * (pc - zu[x]))
                for xc in range(1, wcp - 1):
                    sv = tmp[2 * xc - 1]
                    if 2 * xc < wp - 1:
                        sv += tmp[2 * xc]
                    rck[xc] += sv


@kernel
def _prolong_add(z, ec):
    """z += P ec on the interior."""
    c, hp, wp = z.shape
    for y in prange(1, hp - 1):
        for k in range(c):
            zr, er = z[k, y], ec[k, (y + 1) // 2]
            for x in range(1, wp - 1):
                zr[x] += er[(x + 1) // 2]


@kernel
def _coarsen(w0, wx, wy, factor, c0, cx, cy):
    """Coarse weights (all padded): block sums of w0; a coarse edge = factor x the two fine edges
    it crosses. Fine indices past the interior land on the zero frame, so no test is needed."""
    cw, hcp, wcp = c0.shape
    for yc in prange(hcp):
        for k in range(cw):
            for xc in range(wcp):
                if yc == 0 or xc == 0 or yc == hcp - 1 or xc == wcp - 1:
                    c0[k, yc, xc] = 0.0
                    cx[k, yc, xc] = 0.0
                    cy[k, yc, xc] = 0.0
                    continue
                y, x = 2 * yc - 1, 2 * xc - 1
                c0[k, yc, xc] = (w0[k, y, x] + w0[k, y, x + 1] + w0[k, y + 1, x]
                                 + w0[k, y + 1, x + 1])
                cx[k, yc, xc] = factor * (wx[k, y, x + 1] + wx[k, y + 1, x + 1])
                cy[k, yc, xc] = factor * (wy[k, y + 1, x] + wy[k, y + 1, x + 1])


@kernel
def _inverse_diagonal(w0, wx, wy, out):
    """1 / diag(A) where the diagonal is > 0, else 0 (a pixel with no term is in A's null space)."""
    cw, hp, wp = w0.shape
    for y in prange(hp):
        for k in range(cw):
            for x in range(wp):
                d = 0.0
                if 0 < y < hp - 1 and 0 < x < wp - 1:
                    d = (w0[k, y, x] + wx[k, y, x] + wx[k, y, x - 1] + wy[k, y, x]
                         + wy[k, y - 1, x])
                out[k, y, x] = 1.0 / d if d > 0.0 else 0.0


def _dense_pinv(w0, wx, wy):
    """Pseudo-inverses of the (tiny) coarsest operator on its interior, one per weight channel."""
    cw, hp, wp = w0.shape
    h, w = hp - 2, wp - 2
    n = h * w
    idx = np.arange(n).reshape(h, w)
    out = np.empty((cw, n, n))
    for k in range(cw):
        a = np.diag(np.asarray(w0[k, 1:-1, 1:-1], dtype=np.float64).ravel())
        for (i, j) in np.ndindex(h, w):
            for (di, dj, q) in ((0, 1, wx[k, i + 1, j + 1]), (1, 0, wy[k, i + 1, j + 1])):
                if i + di < h and j + dj < w and q != 0.0:
                    u, v = idx[i, j], idx[i + di, j + dj]
                    a[u, u] += q
                    a[v, v] += q
                    a[u, v] -= q
                    a[v, u] -= q
        # eigenvalues below 1e-12 of the largest are treated as null modes (e.g. alpha = 0)
        out[k] = np.linalg.pinv(a, rcond=1e-12, hermitian=True)
    return out


class Multigrid:
    """V-cycle preconditioner ``z = B r`` for A with padded planar weights (see module docstring).

    ``w0, wx, wy``: Cw x (H+2) x (W+2), frame and masked edges 0. ``dtype`` of the vectors and
    weights of every level (float32 halves the memory traffic; the preconditioner's own error is
    far above float32 round-off). ``sweeps``: smoothing sweeps before and after each correction
    (an int, or one per level, the last repeated for coarser ones); ``sor``: over-relaxation of
    the red-black sweeps, in (0, 2);
    ``smoother``: "rbgs" (red-black Gauss-Seidel) or "jacobi" (damped by ``omega``). The
    returned z lives in a buffer reused by the next call (copy it to keep it). ``invd0``: the
    finest level's inverse diagonal if the caller has it already (as the IRLS pass computes it).
    """

    def __init__(self, w0, wx, wy, dtype=np.float32, sweeps=1,
                 edge_factor=COARSE_EDGE_FACTOR, coarsest=COARSEST_CELLS, omega=OMEGA,
                 smoother="rbgs", invd0=None, sor=SOR_OMEGA):
        if smoother not in ("rbgs", "jacobi"):
            raise ValueError(f"Multigrid: smoother = {smoother!r}; use 'rbgs' or 'jacobi'")
        self.smoother = smoother
        per_level = tuple(int(v) for v in np.atleast_1d(sweeps))
        if not per_level or min(per_level) < 1:
            raise ValueError(f"Multigrid: sweeps = {sweeps} must be >= 1 (or a sequence of them)")
        self.dtype = np.dtype(dtype)
        self.per_level, self.omega = per_level, float(omega)
        if not 0.0 < sor < 2.0:
            raise ValueError(f"Multigrid: sor = {sor} must lie in (0, 2)")
        self.om = float(sor)
        lv = [tuple(np.ascontiguousarray(a, dtype=self.dtype) for a in (w0, wx, wy))]
        while (lv[-1][0].shape[1] - 2) * (lv[-1][0].shape[2] - 2) > coarsest:
            cw, hp, wp = lv[-1][0].shape
            shape = (cw, (hp - 2 + 1) // 2 + 2, (wp - 2 + 1) // 2 + 2)
            cl = tuple(np.empty(shape, dtype=self.dtype) for _ in range(3))
            _coarsen(*lv[-1], float(edge_factor), *cl)
            lv.append(cl)
        self.levels = lv
        self.invd = [] if invd0 is None else [np.asarray(invd0, dtype=self.dtype)]
        for ws in lv[len(self.invd):-1]:
            d = np.empty_like(ws[0])
            _inverse_diagonal(*ws, d)
            self.invd.append(d)
        self.pinv = _dense_pinv(*lv[-1])
        self.buffers = None

    def sweeps(self, level):
        """Smoothing sweeps before (and after) the correction on ``level`` (0: finest)."""
        return self.per_level[min(level, len(self.per_level) - 1)]

    def __call__(self, r):
        r = np.ascontiguousarray(r, dtype=self.dtype)
        if self.buffers is None or self.buffers[0][0].shape[0] != r.shape[0]:
            self.buffers = []
            for lv, nxt in zip(self.levels[:-1], self.levels[1:]):
                self.buffers.append((np.zeros((r.shape[0],) + lv[0].shape[1:], self.dtype),
                                     np.zeros((r.shape[0],) + nxt[0].shape[1:], self.dtype)))
        return self._cycle(0, r)

    def _cycle(self, level, b):
        if level == len(self.levels) - 1:
            c, hp, wp = b.shape
            flat = b[:, 1:-1, 1:-1].reshape(c, -1).astype(np.float64)
            z = np.zeros_like(b)
            for k in range(c):
                sol = self.pinv[k if self.pinv.shape[0] > 1 else 0] @ flat[k]
                z[k, 1:-1, 1:-1] = sol.reshape(hp - 2, wp - 2)
            return z
        ws, invd = self.levels[level], self.invd[level]
        if self.smoother == "rbgs":
            return self._cycle_rbgs(level, b, ws, invd)
        z = np.empty_like(b)
        _scaled(b, invd, self.omega, z)
        sweeps = self.sweeps(level)
        tmp = np.zeros_like(b) if sweeps > 1 else None
        for _ in range(sweeps - 1):
            _jacobi(z, b, *ws, invd, self.omega, tmp)
            z, tmp = tmp, z
        cw, hcp, wcp = self.levels[level + 1][0].shape
        rc = np.empty((b.shape[0], hcp, wcp), dtype=self.dtype)
        _residual_restrict(z, b, *ws, rc)
        _prolong_add(z, self._cycle(level + 1, rc))
        tmp = np.zeros_like(b) if tmp is None else tmp
        for _ in range(sweeps):     # the same (symmetric) smoother: B stays symmetric
            _jacobi(z, b, *ws, invd, self.omega, tmp)
            z, tmp = tmp, z
        return z

    def _cycle_rbgs(self, level, b, ws, invd):
        """Red-black Gauss-Seidel: red, black before the correction, black, red after it (the
        adjoint order, so that B stays symmetric). Each level's z and coarse residual live in
        buffers made once (a returned z is valid until the next call)."""
        z, rc = self.buffers[level]
        _rb_first(z, b, invd, self.om)               # = the red sweep from z = 0
        _rb_sweep(z, b, *ws, invd, 1, self.om)
        sweeps = self.sweeps(level)
        for _ in range(sweeps - 1):
            _rb_sweep(z, b, *ws, invd, 0, self.om)
            _rb_sweep(z, b, *ws, invd, 1, self.om)
        _residual_restrict(z, b, *ws, rc)
        _prolong_add(z, self._cycle(level + 1, rc))
        for _ in range(sweeps):
            _rb_sweep(z, b, *ws, invd, 1, self.om)
            _rb_sweep(z, b, *ws, invd, 0, self.om)
        return z
