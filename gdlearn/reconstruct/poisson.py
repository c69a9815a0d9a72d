"""Screened Poisson reconstruction (Hua et al. 2019, Sec. 5.1, Eq. 18-19): L2 exact, weighted L2, L1.

Convention (the reference solver of Lehtinen et al. 2013 / Kettunen et al. 2015, ``alpha`` = 0.2 by
default in both papers' code): the residual vector is ``[alpha (I - I0), Dx I - Gx, Dy I - Gy]``, so

    L2:  E(I) = alpha^2 ||I - I0||^2 + ||Dx I - Gx||^2 + ||Dy I - Gy||^2  (Eq. 18, lambda = alpha^2)
    L1:  E(I) = sum_p alpha |I_p - I0_p| + |(Dx I - Gx)_p| + |(Dy I - Gy)_p|

where |.| of a colour residual is its Euclidean length over the channels (the reference solver
reweights a pixel's RGB residual as one vector).

* :func:`poisson_l2` without weights and without missing data is solved exactly by the DCT
  (:mod:`.dct`). With ``weights`` (or with non-finite input, whose terms get weight 0) the weighted
  normal equations
  ``(alpha^2 W0 + Dx^T Wx Dx + Dy^T Wy Dy) I = alpha^2 W0 I0 + Dx^T Wx Gx + Dy^T Wy Gy``
  are solved by conjugate gradients preconditioned with the DCT solve of the same operator with
  every weight replaced by its mean, rescaled by the diagonal (see _DCTPreconditioner).
* :func:`poisson_l1` minimises the L1 energy by iteratively reweighted least squares (IRLS, as
  the STAR notes after Eq. 19): the term weights become ``1 / (|e| + eps)`` from the current
  residual ``e``, ``eps`` starting at ``eps0`` and multiplied by ``eps_decay`` per reweighting.
"""
from __future__ import annotations

import time

import numpy as np

from gdlearn.reconstruct.conventions import Problem, Reconstruction, expand_like, prepare
from gdlearn.reconstruct.dct import laplacian_eigenvalues, solve_shifted_laplacian
from gdlearn.reconstruct.irls import irls_multigrid
from gdlearn.reconstruct.operators import (apply_normal, cg_direction, cg_update, dot_channels,
                        fill_irls_weights, irls_residual_lengths, l1_energy, normal_diagonal,
                        normal_rhs,
                        sum_inverse_lengths as _sum_inverse, uniform_residual, uniform_rhs)

__all__ = ["poisson_l2", "poisson_l1", "pcg"]

#: alpha^2 W0 below this fraction of the gradient weights is "pure gradient integration": the
#: constant mode is then fixed by the data-term balance, not solved for (see _fix_constant).
NEGLIGIBLE_SCREENING = 1e-12


def _check_alpha(alpha: float) -> float:
    alpha = float(alpha)
    if not np.isfinite(alpha) or alpha < 0.0:
        raise ValueError(f"alpha = {alpha!r}: the screening weight must be a finite number >= 0 "
                         "(0.2 is the papers' default; 0 integrates the gradients alone)")
    return alpha


class _DCTPreconditioner:
    """z = S^-1/2 M^-1 S^-1/2 r: the DCT solve of M = c0 I + c1 L (every weight replaced by its
    mean), symmetrically rescaled by S = diag(A) / diag(M) so that regions whose weights are much
    larger or smaller than the mean (IRLS weights span many decades) are scaled correctly.
    With uniform weights S = 1 and M = A: PCG converges in one step."""

    def __init__(self, shape, w0, wx, wy, jacobi=True, dtype=np.float64):
        self.dtype = dtype
        h, w, c = shape
        self.eig = laplacian_eigenvalues(h, w)
        self.c0 = float(w0.mean())
        n_diff = (max(w - 1, 0) * h + max(h - 1, 0) * w) * c
        # mean over the defined differences only: the masked column / row always weigh 0
        self.c1 = float((wx.sum() + wy.sum()) / n_diff) if n_diff else 0.0
        if self.c1 <= 0.0:
            self.c1 = 1.0                 # no gradient term at all: M = c0 I + L is still SPD
        if self.c0 <= NEGLIGIBLE_SCREENING * self.c1:
            self.c0 = 0.0                 # pseudo-inverse on the constant mode (fixed afterwards)
        self.scale = None
        if jacobi:
            da = normal_diagonal(w0, wx, wy, np.empty(shape))
            ones = np.ones(shape)
            mx = ones.copy()
            mx[:, -1] = 0.0
            my = ones.copy()
            my[-1] = 0.0
            dm = normal_diagonal(np.full(shape, self.c0), self.c1 * mx, self.c1 * my, ones)
            ok = (da > 0) & (dm > 0)
            self.scale = np.where(ok, np.sqrt(dm / np.where(ok, da, 1.0)), 1.0)

    def __call__(self, r):
        if self.scale is None:
            return solve_shifted_laplacian(r, self.c0, self.c1, eig=self.eig, dtype=self.dtype)
        z = solve_shifted_laplacian(r * self.scale, self.c0, self.c1, eig=self.eig,
                                    dtype=self.dtype)
        z *= self.scale
        return z


def pcg(b, x, w0, wx, wy, precond, tol=1e-10, maxiter=200):
    """Preconditioned conjugate gradients on ``A x = b``, one independent system per channel.

    ``A = W0 + Dx^T Wx Dx + Dy^T Wy Dy`` (see :mod:`.operators`). ``x`` is the initial guess and
    is updated in place. Returns (x, history, iterations); history[i] = ||b - A x_i|| / ||b||
    over all channels, history[0] for the initial guess.
    """
    ap = np.empty_like(x)
    apply_normal(x, w0, wx, wy, ap)
    r = b - ap
    bnorm = float(np.sqrt(dot_channels(b, b).sum()))
    if bnorm == 0.0:
        bnorm = 1.0                        # b = 0: measure the absolute residual instead
    history = [float(np.sqrt(dot_channels(r, r).sum())) / bnorm]
    z = precond(r)
    p = z.copy()
    rz = dot_channels(r, z)
    it = 0
    while it < maxiter and history[-1] > tol:
        pap = apply_normal(p, w0, wx, wy, ap)
        # a channel whose residual is already exactly 0 has pAp = 0: leave it alone
        a = np.where(pap > 0.0, rz / np.where(pap > 0.0, pap, 1.0), 0.0)
        rr = cg_update(x, r, p, ap, a)
        it += 1
        history.append(float(np.sqrt(rr.sum())) / bnorm)
        z = precond(r)
        rz_new = dot_channels(r, z)
        beta = np.where(rz > 0.0, rz_new / np.where(rz > 0.0, rz, 1.0), 0.0)
        cg_direction(p, z, beta)
        rz = rz_new
    return x, np.asarray(history), it


def _fix_constant(x, i0, w0):
    """Pure gradient integration leaves the constant free: choose it so that sum W0 (I - I0) = 0,
    the identity every exact solution with alpha > 0 satisfies (1^T Dx^T = 0); with uniform
    weights this is "the mean of I equals the primal's mean". No valid primal at all: mean 0."""
    ws = w0.sum(axis=(0, 1))
    wd = (w0 * (i0 - x)).sum(axis=(0, 1))
    shift = np.where(ws > 0, wd / np.where(ws > 0, ws, 1.0), -x.mean(axis=(0, 1)))
    x += shift[None, None, :]
    return x


def _initial_guess(i0, v0):
    """The primal, with missing pixels set to their channel's mean over valid pixels."""
    n = v0.sum(axis=(0, 1))
    mean = np.where(n > 0, i0.sum(axis=(0, 1)) / np.maximum(n, 1), 0.0)
    return np.where(v0 > 0, i0, mean[None, None, :])


def _weighted_system(prob: Problem, alpha, weights, counts):
    """Per-term weight arrays (alpha^2 folded into w0), missing and masked terms at 0."""
    _, _, _, v0, vx, vy = prob.clean()
    w0, wx, wy = v0 * (alpha * alpha), vx.copy(), vy.copy()
    if weights is None:
        return w0, wx, wy
    if isinstance(weights, dict):
        unknown = set(weights) - {"primal", "gx", "gy"}
        if unknown:
            raise ValueError(f"weights: unknown keys {sorted(unknown)}; use 'primal', 'gx', 'gy'")
        weights = (weights.get("primal", 1.0), weights.get("gx", 1.0), weights.get("gy", 1.0))
    if len(weights) != 3:
        raise ValueError("weights: give (w_primal, w_gx, w_gy) or a dict with keys "
                         "'primal', 'gx', 'gy' (arrays H x W, H x W x C, or scalars)")
    for name, wk, target in zip(("weights.primal", "weights.gx", "weights.gy"), weights,
                                (w0, wx, wy)):
        wk = np.asarray(wk, dtype=np.float64)
        if wk.ndim == 0:
            wk = np.full(prob.shape[:2], float(wk))
        vals, valid = expand_like(name, wk, prob.shape, counts)
        target *= vals * valid
    return w0, wx, wy


def _solve_weighted(prob, w0, wx, wy, x0, tol, maxiter, dtype=np.float64):
    i0, gx, gy, v0, _, _ = prob.clean()
    b = np.empty_like(i0)
    normal_rhs(i0, gx, gy, w0, wx, wy, b)
    pre = _DCTPreconditioner(prob.shape, w0, wx, wy, dtype=dtype)
    x, hist, it = pcg(b, x0, w0, wx, wy, pre, tol=tol, maxiter=maxiter)
    if pre.c0 == 0.0:
        _fix_constant(x, i0, w0 if w0.any() else v0)
    return x, hist, it


def _exact_l2(prob: Problem, alpha: float, residual: bool = True):
    """The exact DCT solve for complete data; returns (image, relative residual or None when
    ``residual`` is False -- IRLS's start needs no report and saves a pass)."""
    a2 = alpha * alpha
    b = np.empty_like(prob.primal)
    uniform_rhs(prob.primal, prob.gx, prob.gy, a2, b)
    x = solve_shifted_laplacian(b, a2, 1.0, mean=prob.primal.mean(axis=(0, 1)))
    if not residual:
        return x, None
    rr, bb = uniform_residual(x, b, a2)
    return x, float(np.sqrt(rr / bb)) if bb > 0 else float(np.sqrt(rr))


def _guard(x, prob, counts):
    """Last line of defence: a non-finite result pixel falls back to the primal (counted)."""
    bad = ~np.isfinite(x)
    if bad.any():
        counts["output_fallback"] = int(bad.sum())
        x = np.where(bad, prob.clean()[0], x)
    return x


def poisson_l2(primal, gx, gy, alpha: float = 0.2, *, weights=None, tol: float = 1e-10,
               maxiter: int = 500, precond_dtype=np.float64) -> Reconstruction:
    """Screened Poisson reconstruction with the L2 norm (Eq. 18-19, lambda = alpha^2).

    Without ``weights`` and without non-finite input: the exact DCT solve; ``history`` holds its
    relative residual of the normal equations. Otherwise ``weights = (w_primal, w_gx, w_gy)`` (or
    a dict; arrays H x W / H x W x C or scalars, >= 0) multiply the three terms of the energy and
    the normal equations are solved by DCT-preconditioned CG to relative residual ``tol`` or
    ``maxiter`` steps (``history``: relative residual per CG iteration). ``alpha = 0`` integrates
    the gradients alone, the free constant fixed to the primal's (weighted) mean.
    """
    t0 = time.perf_counter()
    alpha = _check_alpha(alpha)
    prob = prepare(primal, gx, gy)
    counts = dict(prob.nonfinite)
    if weights is None and prob.complete:
        x, res = _exact_l2(prob, alpha)
        return Reconstruction(prob.finish(x), np.array([res]), "relative residual", counts, 1,
                              {"solver": "dct", "seconds": time.perf_counter() - t0})
    w0, wx, wy = _weighted_system(prob, alpha, weights, counts)
    i0, _, _, v0, _, _ = prob.clean()
    x, hist, it = _solve_weighted(prob, w0, wx, wy, _initial_guess(i0, v0), tol, maxiter,
                                  precond_dtype)
    x = _guard(x, prob, counts)
    return Reconstruction(prob.finish(x), hist, "relative residual", counts, it,
                          {"solver": "pcg-dct", "seconds": time.perf_counter() - t0})


def poisson_l1(primal, gx, gy, alpha: float = 0.2, *, irls_iterations: int = 20,
               eps0: float = 0.05, eps_decay: float = 0.5, cg_iterations: int = 50,
               tol: float | None = None, precond_dtype=np.float32,
               preconditioner: str = "multigrid", mg_sweeps: int = 1) -> Reconstruction:
    """Screened Poisson reconstruction with the L1 norm (Eq. 18, n = 1) by IRLS.

    Outer iteration 0 solves the L2 problem (exactly by DCT when the data are complete); each of
    the next ``irls_iterations - 1`` reweights every term by ``1 / (|e| + eps)`` (colour length of
    its residual; normalised to mean 1 as in the reference solver on the DCT path, scaled by eps on
    the multigrid path -- the same step), eps = eps0 * eps_decay^(k-1),
    and runs preconditioned CG from the current image for at most ``cg_iterations`` steps.

    ``preconditioner="multigrid"`` (default, :mod:`!.irls`): CG on the float32 correction with a
    V-cycle of ``mg_sweeps`` red-black symmetric-SOR sweeps (omega 1.2, :mod:`!.multigrid`; an
    int or one per level), stopped when the
    residual has dropped to ``tol`` (default 0.5) times its value at the start of the
    reweighting -- typically one or two steps; ``precond_dtype`` (float32 by default) is the
    precision of that correction solve, the outer residual stays float64. ``preconditioner="dct"``:
    the Jacobi-scaled DCT preconditioner (``_DCTPreconditioner``), stopped when the relative
    residual of the reweighted normal equations is below ``tol`` (default 1e-2;
    ``precond_dtype`` sets the DCTs' precision). ``tol=0`` runs every step.

    Defaults: the reference solver's L1D preset (20 reweightings, eps0 = 0.05 halving, at most 50
    CG steps each); equivalence is judged by the energy and error reached, not the step count.
    Measured on the 320 x 180 test of benchmarks/bench_reconstruct.py (1 % gradient outliers):
    the L1D emulation (20 x 50 plain CG) ends at energy 27916, RMS error 0.073; the multigrid
    default at 27910 (ratio 0.99977; 25 CG steps in all), RMS error 0.030; the DCT path at 28026
    (+0.4 %), 0.069. (Before SOR: two Gauss-Seidel sweeps, ratio 0.99983, 22 steps.)
    ``history``: the L1 energy after each outer iteration (``history[0]``: the L2 start).
    Missing (non-finite) input gets weight 0.
    """
    t0 = time.perf_counter()
    alpha = _check_alpha(alpha)
    if irls_iterations < 1 or cg_iterations < 0 or eps0 < 0 or not 0 < eps_decay <= 1:
        raise ValueError("poisson_l1: need irls_iterations >= 1, cg_iterations >= 0, eps0 >= 0 and "
                         f"0 < eps_decay <= 1 (got {irls_iterations}, {cg_iterations}, {eps0}, "
                         f"{eps_decay}); the reference defaults are 20, 50, 0.05, 0.5")
    if preconditioner not in ("multigrid", "dct"):
        raise ValueError(f"poisson_l1: preconditioner = {preconditioner!r}; use 'multigrid' "
                         "(default) or 'dct'")
    if tol is None:
        tol = 0.5 if preconditioner == "multigrid" else 1e-2
    prob = prepare(primal, gx, gy)
    counts = dict(prob.nonfinite)
    if prob.complete:
        x, _ = _exact_l2(prob, alpha, residual=False)
        inner = [0]
    else:
        w0, wx, wy = _weighted_system(prob, alpha, None, counts)
        i0, _, _, v0, _, _ = prob.clean()
        # the L2 start with missing data: solved tightly (every later step starts from it)
        x, _, it = _solve_weighted(prob, w0, wx, wy, _initial_guess(i0, v0), 1e-10,
                                   max(cg_iterations, 1), np.float64)
        inner = [it]
    if preconditioner == "multigrid":
        x, history, steps = irls_multigrid(prob, x, alpha, irls_iterations, eps0, eps_decay,
                                           cg_iterations, tol, dtype=precond_dtype,
                                           sweeps=mg_sweeps)
        inner += steps
    else:
        x, history = _irls_dct(prob, x, alpha, irls_iterations, eps0, eps_decay, cg_iterations,
                               tol, precond_dtype, inner)
    x = _guard(x, prob, counts)
    return Reconstruction(prob.finish(x), np.asarray(history), "L1 energy", counts,
                          irls_iterations, {"solver": f"irls-pcg-{preconditioner}",
                                            "cg_iterations": inner,
                                            "seconds": time.perf_counter() - t0})


def _irls_dct(prob, x, alpha, irls_iterations, eps0, eps_decay, cg_iterations, tol, dtype, inner):
    """Reweightings 1 .. irls_iterations - 1 with the DCT-preconditioned solve (appends the CG
    steps to ``inner``); returns (x, L1 energy history)."""
    i0, cgx, cgy, v0, vx, vy = prob.clean()
    h, w, _ = prob.shape
    e0, ex, ey = (np.empty((h, w)) for _ in range(3))
    irls_residual_lengths(x, i0, cgx, cgy, alpha, v0, vx, vy, e0, ex, ey)
    history = [l1_energy(e0, ex, ey)]
    w0, wx, wy = (np.empty_like(x) for _ in range(3))
    for k in range(1, irls_iterations):
        eps = eps0 * eps_decay ** (k - 1)
        _irls_weights(prob, alpha, eps, e0, ex, ey, w0, wx, wy)
        x, _, it = _solve_weighted(prob, w0, wx, wy, x, tol, cg_iterations, dtype)
        inner.append(it)
        irls_residual_lengths(x, i0, cgx, cgy, alpha, v0, vx, vy, e0, ex, ey)
        history.append(l1_energy(e0, ex, ey))
    return x, history


def _irls_weights(prob, alpha, eps, e0, ex, ey, w0, wx, wy):
    """IRLS weights 1 / (|e| + eps), normalised to mean 1 over the defined terms, into w0/wx/wy."""
    # eps = 0 (pure IRLS) must not divide by an exactly-zero residual: floor it far below the
    # largest residual; the normalisation then divides by the largest weight first (no overflow).
    emax = max(e0.max(), ex.max(), ey.max())
    eps = max(eps, 1e-12 * emax, 1e-300)
    qmax = 1.0 / eps
    h, w = e0.shape
    n = h * w + h * max(w - 1, 0) + w * max(h - 1, 0)
    total = _sum_inverse(e0, ex, ey, eps, qmax)
    s = n / total / qmax             # weights = s / (|e| + eps) have mean 1
    _, _, _, v0, vx, vy = prob.clean()
    fill_irls_weights(e0, ex, ey, eps, s, alpha * alpha, v0, vx, vy, w0, wx, wy)
