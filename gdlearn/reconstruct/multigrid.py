"""A multigrid V-cycle preconditioner for the weighted screened Poisson operator, on the red-black
split layout of :mod:`.split` -- the inner solve of L1 by IRLS (Hua et al. 2019, Sec. 5.1):
the reweighting makes the weights span many decades, where a DCT solve of the mean-weight
operator is a poor preconditioner.

Operator (as in :mod:`.operators`): ``A = W0 + Dx^T Wx Dx + Dy^T Wy Dy``.

Layout: see :mod:`.split` (padded vectors C x (H+2) x 2 x Wh, each row its even then its odd
columns, weights Cw x ... with a zero frame): every stencil runs without boundary tests, and a
red-black half-sweep touches only its colour's contiguous half rows. The stencils live in
:mod:`.mg_kernels`, passes fusing several of them in :mod:`.mg_fused`.

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

from gdlearn.reconstruct import mg_fused as mf
from gdlearn.reconstruct import mg_kernels as mk
from gdlearn.reconstruct.split import from_split, split_shape, to_split

__all__ = ["Multigrid", "COARSE_EDGE_FACTOR", "COARSEST_CELLS", "OMEGA", "SOR_OMEGA",
           "FUSED_MIN_SIZE"]

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
#: Levels whose vectors have at least this many values (~1 MB of float32) pre-smooth, compute the
#: residual and restrict it in one fused pass (:func:`.mg_fused.presmooth_restrict`); it saves
#: memory traffic, which costs only where a level is not cache-resident: at 64 x 64 x 3 the two
#: passes take 16 us, the fused one 38 us; at 1280 x 720 x 3, 4.5 and 3.2 ms (one thread).
FUSED_MIN_SIZE = 1 << 18


def _dense_pinv(w0, wx, wy):
    """Pseudo-inverses of the (tiny) coarsest operator, one per weight channel; weights H x W x Cw
    (natural order, masked last column / row 0)."""
    h, w, cw = w0.shape
    n = h * w
    idx = np.arange(n).reshape(h, w)
    out = np.empty((cw, n, n))
    for k in range(cw):
        a = np.diag(np.asarray(w0[..., k], dtype=np.float64).ravel())
        for (i, j) in np.ndindex(h, w):
            for (di, dj, q) in ((0, 1, wx[i, j, k]), (1, 0, wy[i, j, k])):
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
    """V-cycle preconditioner ``z = B r`` for A with split-layout weights (see module docstring).

    ``w0, wx, wy``: Cw x (H+2) x 2 x Wh (:mod:`.split`), frame and masked edges 0; ``width``: the
    interior width W. ``dtype`` of the vectors and weights of every level (float32 halves the
    memory traffic; the preconditioner's own error is far above float32 round-off). ``sweeps``:
    smoothing sweeps before and after each correction (an int, or one per level, the last
    repeated for coarser ones); ``sor``: over-relaxation of the red-black sweeps, in (0, 2);
    ``smoother``: "rbgs" (red-black Gauss-Seidel) or "jacobi" (damped by ``omega``). ``r`` and
    the returned z are split-layout vectors; z lives in a buffer reused by the next call (copy
    it to keep it). ``invd0``: the finest level's inverse diagonal if the caller has it already
    (as the IRLS pass computes it). ``reuse``: a Multigrid of the previous reweighting whose
    arrays (coarse weights, diagonals, cycle buffers) this one takes over -- fresh tens of MB
    per reweighting cost page faults on first touch (~3.5 ms per 11 MB measured); the old one
    must not be used afterwards.
    """

    def __init__(self, w0, wx, wy, width, dtype=np.float32, sweeps=1,
                 edge_factor=COARSE_EDGE_FACTOR, coarsest=COARSEST_CELLS, omega=OMEGA,
                 smoother="rbgs", invd0=None, sor=SOR_OMEGA, reuse=None):
        if smoother not in ("rbgs", "jacobi"):
            raise ValueError(f"Multigrid: smoother = {smoother!r}; use 'rbgs' or 'jacobi'")
        self.smoother = smoother
        per_level = tuple(int(v) for v in np.atleast_1d(sweeps))
        if not per_level or min(per_level) < 1:
            raise ValueError(f"Multigrid: sweeps = {sweeps} must be >= 1 (or a sequence of them)")
        if not 0.0 < sor < 2.0:
            raise ValueError(f"Multigrid: sor = {sor} must lie in (0, 2)")
        if w0.ndim != 4 or w0.shape[3] != (int(width) + 3) // 2:
            raise ValueError(f"Multigrid: weights of shape {w0.shape} are not the split layout "
                             f"of width {width}")
        self.dtype = np.dtype(dtype)
        self.per_level = per_level
        # scalars in the vectors' dtype: a float64 scalar would widen the float32 loops
        self.omega, self.om = self.dtype.type(omega), self.dtype.type(sor)
        lv = [tuple(np.ascontiguousarray(a, dtype=self.dtype) for a in (w0, wx, wy))]
        if reuse is not None and (reuse.dtype != self.dtype or reuse.levels[0][0].shape
                                  != lv[0][0].shape or reuse.widths[0] != int(width)):
            reuse = None
        self.widths = [int(width)]
        while (lv[-1][0].shape[1] - 2) * self.widths[-1] > coarsest:
            cw, h, w = lv[-1][0].shape[0], lv[-1][0].shape[1] - 2, self.widths[-1]
            shape = split_shape(cw, (h + 1) // 2, (w + 1) // 2)
            if (reuse is not None and len(reuse.levels) > len(lv)
                    and reuse.levels[len(lv)][0].shape == shape):
                cl = reuse.levels[len(lv)]          # coarsen writes every slot
            else:
                cl = tuple(np.empty(shape, dtype=self.dtype) for _ in range(3))
            mk.coarsen(*lv[-1], self.dtype.type(edge_factor), *cl, w)
            lv.append(cl)
            self.widths.append((w + 1) // 2)
        self.levels = lv
        self.invd = [] if invd0 is None else [np.asarray(invd0, dtype=self.dtype)]
        for i in range(len(self.invd), len(lv) - 1):
            # inverse_diagonal writes the interior only: a reused array's frame is still 0
            # (not level 0's: without invd0 the old one may be the caller's array)
            reusable = (reuse is not None and 0 < i < len(reuse.invd)
                        and reuse.invd[i].shape == lv[i][0].shape)
            d = reuse.invd[i] if reusable else np.zeros_like(lv[i][0])
            mk.inverse_diagonal(*lv[i], d, self.widths[i])
            self.invd.append(d)
        self.pinv = _dense_pinv(*(from_split(a, self.widths[-1]) for a in lv[-1]))
        self.buffers = reuse.buffers if reuse is not None else None

    def sweeps(self, level):
        """Smoothing sweeps before (and after) the correction on ``level`` (0: finest)."""
        return self.per_level[min(level, len(self.per_level) - 1)]

    def __call__(self, r):
        r = np.ascontiguousarray(r, dtype=self.dtype)
        if self.buffers is None or (self.buffers and self.buffers[0][0].shape[0] != r.shape[0]):
            self.buffers = []
            for lv, nxt in zip(self.levels[:-1], self.levels[1:]):
                self.buffers.append((np.zeros((r.shape[0],) + lv[0].shape[1:], self.dtype),
                                     np.zeros((r.shape[0],) + nxt[0].shape[1:], self.dtype)))
        return self._cycle(0, r)

    def _cycle(self, level, b):
        w = self.widths[level]
        if level == len(self.levels) - 1:
            flat = from_split(b, w)                      # H x W x C, float64
            sol = np.empty_like(flat)
            for k in range(b.shape[0]):
                sol[..., k] = (self.pinv[k if self.pinv.shape[0] > 1 else 0]
                               @ flat[..., k].ravel()).reshape(flat.shape[:2])
            return to_split(sol, self.dtype)
        ws, invd = self.levels[level], self.invd[level]
        if self.smoother == "rbgs":
            return self._cycle_rbgs(level, b, ws, invd, w)
        z = np.empty_like(b)
        mk.scaled(b, invd, self.omega, z)
        sweeps = self.sweeps(level)
        tmp = np.zeros_like(b) if sweeps > 1 else None
        for _ in range(sweeps - 1):
            mk.jacobi(z, b, *ws, invd, self.omega, tmp, w)
            z, tmp = tmp, z
        rc = np.empty((b.shape[0],) + self.levels[level + 1][0].shape[1:], dtype=self.dtype)
        mk.residual_restrict(z, b, *ws, rc, w)
        mk.prolong_add(z, self._cycle(level + 1, rc), w)
        tmp = np.zeros_like(b) if tmp is None else tmp
        for _ in range(sweeps):     # the same (symmetric) smoother: B stays symmetric
            mk.jacobi(z, b, *ws, invd, self.omega, tmp, w)
            z, tmp = tmp, z
        return z

    def _cycle_rbgs(self, level, b, ws, invd, w):
        """Red-black Gauss-Seidel: red, black before the correction, black, red after it (the
        adjoint order, so that B stays symmetric). Each level's z and coarse residual live in
        buffers made once (a returned z is valid until the next call)."""
        z, rc = self.buffers[level]
        wx, wy = ws[1], ws[2]
        sweeps = self.sweeps(level)
        if sweeps == 1 and b.size >= FUSED_MIN_SIZE:    # red from 0, black, restriction fused
            mf.presmooth_restrict(z, b, wx, wy, invd, self.om, rc, w)
        else:
            mf.rb_first_pair(z, b, wx, wy, invd, self.om, w)
            for _ in range(sweeps - 1):
                mk.rb_sweep(z, b, wx, wy, invd, 0, self.om, w)
                mk.rb_sweep(z, b, wx, wy, invd, 1, self.om, w)
            mk.residual_restrict(z, b, *ws, rc, w)
        # z += P ec stays a pass of its own: folded into the two sweeps after it (neighbours'
        # corrections on the fly, coarse rows gathered to natural order) it measured slower,
        # 3.8 ms against 3.4 ms for the three passes at 1280 x 720 x 3 on one thread
        mk.prolong_add(z, self._cycle(level + 1, rc), w)
        for _ in range(sweeps):
            mk.rb_sweep(z, b, wx, wy, invd, 1, self.om, w)
            mk.rb_sweep(z, b, wx, wy, invd, 0, self.om, w)
        return z
