"""Reconstruction: primal image + gradients -> final image (Hua et al. 2019, Sec. 2.3 and Sec. 5).

Works on images alone (numpy / scipy / numba); it knows nothing of rays.

Conventions
-----------
* Images are ``H x W x C`` float64 arrays (``H x W`` is accepted and returned as ``H x W``);
  ``primal``, ``gx`` and ``gy`` must have the same shape (otherwise ``ValueError``).
* Forward differences: ``gx[y, x] ~ I[y, x+1] - I[y, x]``, ``gy[y, x] ~ I[y+1, x] - I[y, x]``.
  The last column of ``gx`` and the last row of ``gy`` are undefined and *masked* (ignored).
  :func:`forward_differences` computes exact gradients in this convention.
* Optional per-pixel variances of the primal and of each gradient, ``{"primal", "gx", "gy"}``,
  or two independent half-buffers ``{"primal": (A, B), ...}`` from which they are estimated
  (:func:`variances_from_halves`: var of the mean = (A - B)^2 / 4).
* Bad data stays contained: NaN / Inf in any input is counted (``result.nonfinite``), zeroed and
  given weight 0 -- treated as missing, never propagated.
* Screened Poisson energy in the reference implementation's convention (Eq. 18 with
  lambda = alpha^2): ``alpha^2 ||I - I0||^2 + ||Dx I - Gx||^2 + ||Dy I - Gy||^2``; ``alpha = 0.2``
  is the papers' default; ``alpha = 0`` integrates the gradients alone, the free constant fixed
  to the primal's mean.

API: every solver returns a :class:`Reconstruction`
---------------------------------------------------
``Reconstruction(image, history, history_kind, nonfinite, iterations, info)``

* :func:`control_variates` ``(primal, gx, gy, iterations=50, *, variances=None, halves=None,
  iterate_variance_divisor=5.0)`` -- Eq. 11-14 (uniform, Algorithm 1) and Eq. 20-22 (weighted);
  history: RMS change per iteration. :func:`cv_history` records every iteration (and the error
  against a reference) for plots.
* :func:`poisson_l2` ``(primal, gx, gy, alpha=0.2, *, weights=None, tol=1e-10, maxiter=500,
  precond_dtype=np.float64)`` -- exact DCT solve (Neumann) or, with weights / missing data,
  Jacobi-scaled DCT-preconditioned CG; history: relative residual of the normal equations.
* :func:`poisson_l1` ``(primal, gx, gy, alpha=0.2, *, irls_iterations=20, eps0=0.05,
  eps_decay=0.5, cg_iterations=50, tol=None, precond_dtype=np.float32,
  preconditioner="multigrid", mg_sweeps=2)`` -- IRLS (the reference solver's L1D preset); each
  reweighting solves a float32 correction by CG with a multigrid V-cycle (:mod:`.multigrid`, on
  the padded planar layout of :mod:`.planar`, driver in :mod:`.irls`) until its residual halves
  -- one or two steps; ``preconditioner="dct"`` keeps the DCT-preconditioned path; history: L1
  energy per reweighting.

Speed at 1280 x 720 x 3 (benchmarks/bench_reconstruct.py, 2 threads, quiet machine, best of 3):
exact L2 0.14 s; 50 uniform CV iterations 0.39 s (vectorised rows; 0.55 s before); weighted L2
4.8 s (35 DCT-preconditioned CG steps); L1 defaults 1.9 s (22 multigrid-preconditioned CG steps;
14 s with the DCT preconditioner), at 0.9998 of the energy of a 20 x 50 plain-CG emulation of the
reference preset. What remains in L1 is a fixed cost per reweighting (residual lengths, weights,
residual, multigrid set-up: ~85 ms x 19), not the CG steps.
"""
from .control_variates import CVHistory, control_variates, cv_history
from .conventions import Reconstruction, forward_differences, variances_from_halves
from .poisson import poisson_l1, poisson_l2

__all__ = ["control_variates", "cv_history", "CVHistory", "poisson_l2", "poisson_l1",
           "Reconstruction", "forward_differences", "variances_from_halves"]
