"""Reconstruction: primal image + gradients -> final image (Hua et al. 2019, Sec. 2.3 and Sec. 5).

Works on images alone (numpy / scipy / numba); it knows nothing of rays.

**Conventions**

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

**API: every solver returns a** :class:`Reconstruction`

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
  preconditioner="multigrid", mg_sweeps=1)`` -- IRLS (the reference solver's L1D preset); each
  reweighting makes its weights, diagonal and float64 residual in one pass over the data, then
  solves a float32 correction by CG with a multigrid V-cycle (symmetric SOR smoothing,
  :mod:`!.multigrid`) until its residual halves -- one or two steps -- whose steps go straight into
  the float64 iterate. All of it runs on the red-black split layout of :mod:`!.split` (each row
  its even, then its odd columns: a half-sweep computes only the colour it moves); driver in
  :mod:`!.irls`. ``preconditioner="dct"`` keeps the DCT-preconditioned path; history: L1 energy
  per reweighting.

Speed at 1280 x 720 x 3, what made the difference and what is left: ``benchmarks/README.md``
(bench_reconstruct).
"""
from gdlearn.reconstruct.control_variates import CVHistory, control_variates, cv_history
from gdlearn.reconstruct.conventions import Reconstruction, forward_differences, variances_from_halves
from gdlearn.reconstruct.poisson import poisson_l1, poisson_l2

__all__ = ["control_variates", "cv_history", "CVHistory", "poisson_l2", "poisson_l1",
           "Reconstruction", "forward_differences", "variances_from_halves"]
