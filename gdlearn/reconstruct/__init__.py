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
  preconditioner="multigrid", mg_sweeps=1)`` -- IRLS (the reference solver's L1D preset); each
  reweighting makes its weights, diagonal and float64 residual in one pass over the data, then
  solves a float32 correction by CG with a multigrid V-cycle (symmetric SOR smoothing,
  :mod:`.multigrid`, on the padded planar layout of :mod:`.planar`, driver in :mod:`.irls`)
  until its residual halves -- one or two steps; ``preconditioner="dct"`` keeps the
  DCT-preconditioned path; history: L1 energy per reweighting.

Speed at 1280 x 720 x 3 (benchmarks/bench_reconstruct.py, 2 threads, best of 3-4): exact L2
0.14-0.16 s; 50 uniform CV iterations 0.36-0.39 s; weighted L2 4.8 s quiet (35 DCT-preconditioned
CG steps); L1 defaults 1.9 s quiet before the fused IRLS pass and SOR smoothing, 1.56 s after
(load ~2; interleaved with the older code in the same run: 1.92 s -> 1.69 s, 1.14x), 26
multigrid-preconditioned CG steps, at 0.99977 of the energy of a 20 x 50 plain-CG emulation of
the reference preset (0.99983 before). Still above the 1 s target: per reweighting one SOR
V-cycle (each half-sweep computes the whole row, twice the needed arithmetic) and the IRLS pass
(~30 ms) remain; the stencils are compute-bound here (a cache-resident image is barely faster per
value), so fusing passes saves little and halving arithmetic (a red-black split layout) is next.
"""
from .control_variates import CVHistory, control_variates, cv_history
from .conventions import Reconstruction, forward_differences, variances_from_halves
from .poisson import poisson_l1, poisson_l2

__all__ = ["control_variates", "cv_history", "CVHistory", "poisson_l2", "poisson_l1",
           "Reconstruction", "forward_differences", "variances_from_halves"]
