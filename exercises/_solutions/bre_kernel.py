"""Reference solution of the exercise "bre-kernel" (the book shows it in a dropdown).

gdlearn's compiled version is ``gdlearn.integrators.photon.volume_estimates.biweight`` (it takes
x^2) inside ``bre_beam``, which sums these terms over the photons a bounding-box hierarchy finds
(``gdlearn.photons.bbh``); this is the term for one photon, written out so that it can be read on
its own.
"""
import math


def biweight(x):
    """Silverman's 2D biweight K2(x) = 3/pi (1 - x^2)^2 for |x| < 1, else 0: int_0^1 K2(x) 2 pi x dx = 1."""
    if abs(x) >= 1.0:
        return 0.0
    a = 1.0 - x * x
    return 3.0 / math.pi * a * a


def bre_contribution(o, w, s, x_p, r, sigma_t, sigma_s, phase, power):
    """K2(d / r) / r^2 Tr(t) sigma_s p Phi (Jarosz et al. 2008, Eq. 20-21), with t = (x_p - o) . w in
    (0, s) -- the Heaviside factors of Eq. 17 -- and Tr at the projected point o + t w."""
    q = [x_p[k] - o[k] for k in range(3)]
    t = sum(q[k] * w[k] for k in range(3))
    if not 0.0 < t < s:
        return 0.0
    d2 = sum((q[k] - t * w[k]) ** 2 for k in range(3))    # the perpendicular offset, not |q|^2 - t^2
    if d2 >= r * r:
        return 0.0
    return biweight(math.sqrt(d2) / r) / (r * r) * math.exp(-sigma_t * t) * sigma_s * phase * power
