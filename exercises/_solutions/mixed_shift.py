"""Reference solution of the exercise "mixed-shift" (the book shows it in a dropdown).

gdlearn's compiled version is ``gdlearn.shifts.volume_photon.mixed_shift`` (it returns the branch as
an integer, NULL / TRANSLATED / REFLECTED), called by G-VPM's camera pass
(``gdlearn.integrators.photon.gvpm_gather``); this is the same construction written out in plain
Python so that it can be read on its own.
"""
import math


def _dist2(a, b):
    return sum((a[k] - b[k]) ** 2 for k in range(3))


def mixed_shift(b, d, d_off, r):
    """Eq. 16 (Gruson et al. 2018): keep the photons of the lens K n K', translate the others by
    d' - d, and reflect those whose translate b* fell into K across the plane through d'."""
    if _dist2(b, d_off) < r * r:                          # already in K': the null shift
        return tuple(b), "null"
    e = tuple(d_off[k] - d[k] for k in range(3))
    bs = tuple(b[k] + e[k] for k in range(3))             # b* = b + (d' - d), always in K'
    if not _dist2(bs, d) < r * r:                         # outside K: nothing else maps there
        return bs, "translated"
    n = math.sqrt(sum(c * c for c in e))
    u = tuple(c / n for c in e)
    k = 2.0 * sum(u[i] * (d_off[i] - bs[i]) for i in range(3))
    return tuple(bs[i] + k * u[i] for i in range(3)), "reflected"   # b' = b* + 2 u^T (d' - b*) u
