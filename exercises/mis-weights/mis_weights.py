"""Exercise "mis-weights" (chapter: Gradient-domain path tracing). Fill in the two functions.

Run ``gdlearn check mis-weights`` to test them (see README.md).
"""
import math


def balance_weight(log_p, log_p_offset, log_jacobian) -> float:
    """Eq. 17, w = p / (p + p_offset * |J|), from log p, log p_offset and log |J| (never exp them
    one by one: the products over a path over- and underflow)."""
    raise NotImplementedError("balance_weight is not written yet (see README.md)")


def forward_contribution(f, p, f_offset, jacobian, weight, failed) -> float:
    """One base sample's term of the forward integral of Eq. 16: weight * (f_offset * J - f) / p,
    or -f / p (weight 1, no offset) when the shift failed."""
    raise NotImplementedError("forward_contribution is not written yet (see README.md)")
