"""Reference solution of the exercise "free-flight" (the book shows it in a dropdown).

gdlearn's own versions are ``gdlearn.kernels.media.medium.sample_distance_1`` and
``sample_distance`` (compiled with numba, with a shortcut for grey media); these are written out
in plain Python so that they can be read on their own.
"""
import math


def free_flight(sigma, t_max, u):
    """t = -log(1 - u) / sigma, written with log1p so that a thin medium keeps its precision."""
    if sigma <= 0.0:
        return t_max, False, 1.0
    t = -math.log1p(-u) / sigma
    if t < t_max:
        return t, True, sigma * math.exp(-sigma * t)
    return t_max, False, math.exp(-sigma * t_max)


def spectral_free_flight(sigma_t, albedo, t_max, u_channel, u):
    """One channel picked uniformly, weights from the balance-heuristic density of all three."""
    c = min(int(u_channel * 3.0), 2)
    t = -math.log1p(-u) / sigma_t[c] if sigma_t[c] > 0.0 else math.inf
    if t < t_max:
        tr = [math.exp(-s * t) for s in sigma_t]
        pdf = sum(s * x for s, x in zip(sigma_t, tr)) / 3.0
        if not pdf > 0.0:
            return t, True, (0.0, 0.0, 0.0)
        return t, True, tuple(a * s * x / pdf for a, s, x in zip(albedo, sigma_t, tr))
    tr = [math.exp(-s * t_max) if s > 0.0 else 1.0 for s in sigma_t]   # 0 * inf would be NaN
    p = sum(tr) / 3.0
    if not p > 0.0:
        return t_max, False, (0.0, 0.0, 0.0)
    return t_max, False, tuple(x / p for x in tr)
