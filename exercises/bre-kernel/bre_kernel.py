"""Exercise "bre-kernel" (chapter: Photons in participating media). Fill in the two functions.

Run ``gdlearn check bre-kernel`` to test them (see README.md).
"""


def biweight(x):
    """Silverman's 2D biweight K2(x) = 3/pi (1 - x^2)^2 for |x| < 1, else 0."""
    raise NotImplementedError("biweight is not written yet (see README.md)")


def bre_contribution(o, w, s, x_p, r, sigma_t, sigma_s, phase, power):
    """One photon's term of the beam radiance estimate along the ray o + t w, 0 < t < s:
    K2(d / r) / r^2 * exp(-sigma_t t) * sigma_s * phase * power, with t the photon's projection onto
    the ray and d its distance from the ray; 0 unless 0 < t < s and d < r."""
    raise NotImplementedError("bre_contribution is not written yet (see README.md)")
