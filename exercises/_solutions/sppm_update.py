"""Reference solution of the exercise "sppm-update" (the book shows it in a dropdown).

gdlearn stores the same statistics in the density form (``D = tau / (pi R^2)``,
``gdlearn.integrators.photon.sppm.accumulate_density`` and ``reduce_radius``); this is the form of
Hachisuka et al. 2008, written out so that it can be read on its own.
"""
import math


def progressive_update(N, r2, tau, M, phi, alpha):
    """(N + alpha M, R^2 (N + alpha M) / (N + M), (tau + Phi) R'^2 / R^2); a pass without photons
    and without history (N + M = 0) changes nothing."""
    if N + M == 0:
        return N, r2, tau
    ratio = (N + alpha * M) / (N + M)
    return N + alpha * M, r2 * ratio, (tau + phi) * ratio


def radiance(tau, r2, n_emitted):
    """tau / (pi R^2 n_emitted)."""
    return tau / (math.pi * r2 * n_emitted)
