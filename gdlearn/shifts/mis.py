"""Balance-heuristic MIS of the forward and backward shifts (STAR, Hua et al. 2019, Eq. 16-17, Sec. 3.5).

The gradient between pixels p and q is estimated from base paths at p shifted to q (forward) and
base paths at q shifted to p (backward); a path reachable both ways is weighted by Eq. 17::

    w_pq(x) = p(x) / (p(x) + p(T_pq(x)) |dT_pq/dx|)  =  1 / (1 + r),   r = p_off |J| / p_base.

Path densities are products of many per-vertex densities, so p_base and p_off can be 1e-300 or
1e300 while their ratio is ordinary: the weight is computed from the ratio r in the log domain
(never forming p_off * J or p_base + p_off * J directly), which neither underflows nor overflows.

A failed or irreversible shift (offset not sampleable, BSDF zero, manifold walk failed ...) gets
weight 1 for the base path and a zero offset contribution (STAR Sec. 3.5): the gradient then falls
back to the finite difference of the two base estimates.
"""
import math

import numpy as np
from gdlearn.kernels.jit import block


#: |log r| beyond which the weight is exactly 0 or 1 in float64 (exp(-746) underflows anyway).
_LOG_CLAMP = 700.0


@block
def mis_weight_from_log_ratio(log_r):
    """1 / (1 + exp(log_r)), stable for any log_r (including +-inf); NaN -> 1 (base keeps its weight)."""
    if log_r != log_r:
        return 1.0
    if log_r > _LOG_CLAMP:
        return 0.0
    if log_r < -_LOG_CLAMP:
        return 1.0
    if log_r > 0.0:                 # 1/(1+e^x) = e^-x/(1+e^-x): keeps full relative precision
        e = math.exp(-log_r)
        return e / (1.0 + e)
    return 1.0 / (1.0 + math.exp(log_r))


@block
def mis_weight(p_base, p_offset, jacobian):
    """Eq. 17 balance weight of the base path, ``w = p_base / (p_base + p_offset |J|)``, in ratio form.

    Invalid inputs never give NaN: a zero, negative or NaN offset density or Jacobian means the offset
    could not have been sampled (weight 1); a zero or NaN base density with a valid offset gives 0.
    """
    j = abs(jacobian)
    if not (p_offset > 0.0) or not (j > 0.0):
        return 1.0
    if not (p_base > 0.0):
        return 0.0
    return mis_weight_from_log_ratio(math.log(p_offset) + math.log(j) - math.log(p_base))


@block
def mis_weight_products(pdfs_base, pdfs_offset, n, log_jacobian):
    """Eq. 17 for path densities given as products of the first n per-vertex densities; the
    products are summed as logs so a long path of tiny densities does not underflow to 0 / 0."""
    lr = log_jacobian
    for i in range(n):
        pb = pdfs_base[i]
        po = pdfs_offset[i]
        if not (po > 0.0):
            return 1.0
        if not (pb > 0.0):
            return 0.0
        lr += math.log(po) - math.log(pb)
    return mis_weight_from_log_ratio(lr)


@block
def shift_weights(p_base, p_offset, jacobian, ok):
    """Weights of one base sample and its shift: ``(w_base, w_offset_factor)``.

    The base contribution f(x) is weighted by w_base; the offset contribution ``f(T(x)) |J|`` by
    w_offset_factor. For a successful reversible shift both equal Eq. 17's w_pq (the same weight
    multiplies ``f(T(x))|J| - f(x)`` in Eq. 16). For a failed / irreversible one w_base = 1 and the
    offset factor is 0 (STAR Sec. 3.5).
    """
    if not ok:
        return 1.0, 0.0
    w = mis_weight(p_base, p_offset, jacobian)
    return w, w


def mis_weight_np(p_base, p_offset, jacobian):
    """Vectorised convenience wrapper (numpy arrays in, float64 array out) for the book and tests."""
    pb, po, j = np.broadcast_arrays(np.asarray(p_base, float), np.asarray(p_offset, float),
                                    np.asarray(jacobian, float))
    out = np.empty(pb.shape)
    flat_out = out.reshape(-1)
    for k, (a, b, c) in enumerate(zip(pb.ravel(), po.ravel(), j.ravel())):
        flat_out[k] = mis_weight(a, b, c)
    return out
