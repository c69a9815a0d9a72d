"""The exact screened Poisson L2 solve by the discrete cosine transform, O(N log N).

With forward differences and masked last column / row (see ``conventions``), the matrix
``L = Dx^T Dx + Dy^T Dy`` is the 5-point Laplacian with Neumann boundaries, and the DCT-II basis
diagonalises it exactly: the 1-D Neumann second-difference matrix of size n has eigenvectors
cos(pi k (i + 1/2) / n) and eigenvalues 4 sin^2(pi k / (2 n)), k = 0..n-1. Hence the normal
equations of Eq. 18-19 (Hua et al. 2019, Sec. 5.1), in the reference implementation's convention

    E(I) = alpha^2 ||I - I0||^2 + ||Dx I - Gx||^2 + ||Dy I - Gy||^2,
    (alpha^2 + L) I = alpha^2 I0 + Dx^T Gx + Dy^T Gy          (Eq. 19 with lambda = alpha^2)

are solved by one forward DCT, one division by ``alpha^2 + lambda_kl`` and one inverse DCT.

The constant mode (k = l = 0, eigenvalue 0) is set directly: multiplying Eq. 19 by the all-ones
vector gives ``alpha^2 sum(I) = alpha^2 sum(I0)`` because ``Dx 1 = Dy 1 = 0``, so the solution's
mean *is* the primal's mean for every alpha > 0 -- and for alpha = 0 (pure gradient integration,
where the constant is free) we fix it to the same value. Doing this explicitly avoids dividing a
round-off-sized number by alpha^2 when alpha is tiny.
"""
from __future__ import annotations

import numpy as np
import scipy.fft as sfft

__all__ = ["laplacian_eigenvalues", "solve_shifted_laplacian"]


def laplacian_eigenvalues(h: int, w: int) -> np.ndarray:
    """Eigenvalues of the Neumann 5-point Laplacian on an h x w grid in DCT-II order, shape (h, w)."""
    ky = 4.0 * np.sin(0.5 * np.pi * np.arange(h) / h) ** 2
    kx = 4.0 * np.sin(0.5 * np.pi * np.arange(w) / w) ** 2
    return ky[:, None] + kx[None, :]


def solve_shifted_laplacian(b: np.ndarray, c0: float, c1: float, mean=None,
                            eig: np.ndarray | None = None, dtype=np.float64) -> np.ndarray:
    """Solve ``(c0 I + c1 L) x = b`` exactly for each channel of an H x W x C array ``b``.

    ``c0 >= 0``, ``c1 > 0``. ``mean`` (per channel, shape (C,)) fixes the mean of ``x`` -- the
    constant mode; if None it is ``sum(b) / (c0 N)`` when c0 > 0 and 0 (the pseudo-inverse) when
    c0 == 0. ``b`` is not modified. ``eig`` may pass precomputed :func:`laplacian_eigenvalues`.
    ``dtype=np.float32`` halves the transform time; only a preconditioner, whose own error is far
    above float32 round-off, should ask for it. The result is always float64.
    """
    h, w, c = b.shape
    if eig is None:
        eig = laplacian_eigenvalues(h, w)
    b = np.asarray(b, dtype=dtype)
    # threads pay off only on large images (thread start-up dominates below ~64k values)
    workers = -1 if b.size >= 1 << 16 else 1
    bh = sfft.dctn(b, type=2, axes=(0, 1), norm="ortho", workers=workers)
    denom = (c0 + c1 * eig).astype(dtype)
    denom[0, 0] = 1.0                 # the constant mode is set below, never divided
    bh /= denom[:, :, None]
    n = h * w
    if mean is not None:
        bh[0, 0, :] = np.sqrt(n) * np.asarray(mean, dtype=np.float64)
    elif c0 > 0.0:
        bh[0, 0, :] = bh[0, 0, :] / c0     # denom[0, 0] was set to 1
    else:
        bh[0, 0, :] = 0.0
    x = sfft.idctn(bh, type=2, axes=(0, 1), norm="ortho", workers=workers, overwrite_x=True)
    return np.asarray(x, dtype=np.float64)
