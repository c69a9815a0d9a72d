"""Per-pixel accumulation of the gradient kernels' samples, shared by gpt's surface and media rows.

A sample of a gradient estimator is the base radiance ``c`` (rgb) and eight rgb rows ``d8``: the
gradient samples D_k (rows 0-3) and the weighted offset contributions S_k (rows 4-7) of the four
shifts (:mod:`gdlearn.integrators.gradients`). A sample with anything non-finite is dropped whole
(and counted by the caller): NaN or Inf never reach an image.
"""
import numpy as np

from gdlearn.kernels.jit import leaf


@leaf
def finite_sample(c, d8):
    """True when the base radiance and all eight shift rows are finite (a loop: this leaf may not
    allocate the temporary of ``np.isfinite(d8)``)."""
    if not (np.isfinite(c[0]) and np.isfinite(c[1]) and np.isfinite(c[2])):
        return False
    for k in range(8):
        for ch in range(3):
            if not np.isfinite(d8[k, ch]):
                return False
    return True


@leaf
def add_sample(acc, c, d8):
    """acc (9, 3) += [c, D_0..D_3, S_0..S_3]."""
    for ch in range(3):
        acc[0, ch] += c[ch]
        for k in range(8):
            acc[1 + k, ch] += d8[k, ch]


@leaf
def store_means(out, y, x, acc, inv):
    """out[:, y, x] = acc * inv: the pixel's per-pass means, one per row of ``acc`` (gpt's nine: L,
    D_k, S_k; gpt-replay's five: L, D_k)."""
    for j in range(acc.shape[0]):
        for ch in range(3):
            out[j, y, x, ch] = acc[j, ch] * inv
