"""Reference solution of the exercise "mis-weights" (the book shows it in a dropdown).

gdlearn's own version is ``gdlearn.shifts.mis.mis_weight_from_log_ratio``; this one is written out
so that it can be read on its own.
"""
import math


def balance_weight(log_p, log_p_offset, log_jacobian) -> float:
    """w = 1 / (1 + r) with log r = log p_offset + log |J| - log p, evaluated without overflow."""
    log_r = log_p_offset + log_jacobian - log_p
    if math.isnan(log_r):
        return 0.5 if log_p == log_p_offset + log_jacobian else 0.0   # inf - inf: equal, or broken input
    if log_r > 0:                       # r > 1: w = exp(-log r) / (1 + exp(-log r)), exp(-log r) <= 1
        e = math.exp(-log_r)
        return e / (1.0 + e)
    return 1.0 / (1.0 + math.exp(log_r))  # r <= 1: exp(log r) <= 1, no overflow


def forward_contribution(f, p, f_offset, jacobian, weight, failed) -> float:
    """weight * (f_offset * J - f) / p; a failed shift: weight 1 and no offset."""
    if failed:
        return -f / p
    return weight * (f_offset * jacobian - f) / p
