"""Exercise "mixed-shift" (chapter: Gradient-domain volumetric photon density estimation). Fill in
the function.

Run ``gdlearn check mixed-shift`` to test it (see README.md).
"""


def mixed_shift(b, d, d_off, r):
    """Eq. 16 of Gruson et al. 2018: the photon b of the ball K = Ball(d, r) moved into the ball
    K' = Ball(d_off, r). Returns ``(b_off, branch)``: b_off a 3-tuple, branch one of "null" (b is in
    K': kept), "translated" (b* = b + (d' - d), outside K) or "reflected" (b* fell into K: reflected
    across the plane through d' perpendicular to u = (d' - d) / |d' - d|). Membership is strict,
    |x - centre| < r."""
    raise NotImplementedError("mixed_shift is not written yet (see README.md)")
