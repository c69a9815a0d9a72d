"""Exercise "free-flight" (chapter: Participating media and volumetric path tracing). Fill in the
two functions.

Run ``gdlearn check free-flight`` to test them (see README.md).
"""
import math


def free_flight(sigma, t_max, u):
    """Free-flight distance by inversion: (t, True, sigma exp(-sigma t)) if t < t_max, else
    (t_max, False, exp(-sigma t_max)); sigma = 0 gives (t_max, False, 1.0)."""
    raise NotImplementedError("free_flight is not written yet (see README.md)")


def spectral_free_flight(sigma_t, albedo, t_max, u_channel, u):
    """Spectral-MIS free flight: (t, scattered, (w_r, w_g, w_b)) with the weights of README.md."""
    raise NotImplementedError("spectral_free_flight is not written yet (see README.md)")
