"""The kernel-vertex shifts of gradient-domain volumetric photon mapping (Gruson et al. 2018, Sec. 4.1-4.2;
PHOTONS.md Sec. 5.2-5.3).

A G-VPM path merges a light subpath ending at the photon b (parent a) with a camera subpath whose
last edge, the camera beam from c, holds the gather point d = c + t w_c. Shifting the pixel moves the
camera beam to c' + t w'_c; the kernel vertices follow (Gruson et al. 2018, Eq. 13: the Jacobian
separates into |db'/db| |dd'/dd|):

* **camera distance copy** (Sec. 4.1, Eq. 14-15): d' = c' + t w'_c, the same distance t on the
  offset's beam. In the (direction, distance) parametrisation of a volume point the distance part of
  the Jacobian is dt'/dt = 1 (:data:`gdlearn.shifts.distance.JACOBIAN`). The shift fails where
  the offset's beam is shorter than t (:func:`camera_distance_copy`); the region of a longer offset
  beam that no base reaches is the reverse shift's failure, so the pair stays unbiased.
* **photon shifts** (Sec. 4.2, Eq. 16), K = Ball(d, r), K' = Ball(d', r), u = (d' - d) / |d' - d|:

  - *simple*: b' = b + (d' - d), a translation (:func:`simple_shift`);
  - *null*: b' = b, free, but only the photons already in K' are reachable;
  - *mixed* (Eq. 16): null if b is in K'; otherwise b* = b + (d' - d), and if b* fell into K (the
    overlap, already covered by the null part) it is reflected across the plane through d'
    perpendicular to u, ``b' = b* + 2 u^T (d' - b*) u`` (:func:`mixed_shift`).

  The mixed shift is a bijection K -> K' with |J| = 1 (PHOTONS.md Sec. 5.3): the translation maps
  K \\ K' onto K' \\ K'' (K'' = Ball(d' + D u, r)); the reflection R' across the plane through d'
  maps K' onto itself and K' \\ K'' onto K' \\ K, so the translated pieces that land in K are moved
  onto exactly the part of K' \\ K the translation missed. Its inverse is the same construction
  from the offset pixel (d' -> d), which returns b exactly (tests/test_shifts_volume_photon.py).
  Translations and reflections preserve volume, hence |db'/db| = 1 (:data:`PHOTON_JACOBIAN`).

Everything here is a pure function of 3-vectors (tuples), callable from numba and from Python.
"""
import math

from gdlearn.kernels.jit import leaf

#: |db'/db| of the simple and the mixed shift (translation, reflection: volume preserving)
PHOTON_JACOBIAN = 1.0
#: outcomes of :func:`mixed_shift` / :func:`simple_shift`: the photon kept (b' = b), translated, or
#: translated and reflected (Eq. 16)
NULL, TRANSLATED, REFLECTED = 0, 1, 2


@leaf
def camera_distance_copy(t, s_offset):
    """Gruson et al. 2018, Eq. 14-15: the gather point's distance t copied onto the offset's camera
    beam of length ``s_offset``. Returns ``(ok, t', dt'/dt)``: fails (ok False) when t > s' -- the
    offset's beam ends (a surface, the end of its medium) before t ("deny due to shorter shift
    camera beam" in the reference code)."""
    if not t <= s_offset:
        return False, 0.0, 0.0
    return True, t, 1.0


@leaf
def _sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@leaf
def _dist2(a, b):
    e = _sub(a, b)
    return e[0] * e[0] + e[1] * e[1] + e[2] * e[2]


@leaf
def simple_shift(b, d, d_off):
    """The simple photon shift (Gruson et al. 2018, Sec. 4.2; Hua et al. 2017's analogue):
    ``b' = b + (d' - d)``. Returns ``(b', TRANSLATED)`` (or NULL when d' = d)."""
    e = _sub(d_off, d)
    kind = NULL if (e[0] == 0.0 and e[1] == 0.0 and e[2] == 0.0) else TRANSLATED
    return (b[0] + e[0], b[1] + e[1], b[2] + e[2]), kind


@leaf
def mixed_shift(b, d, d_off, r):
    """The mixed photon shift, Gruson et al. 2018, Eq. 16, for a photon b in K = Ball(d, r) moved
    to K' = Ball(d', r): returns ``(b', kind)``, kind NULL (b in K': b' = b), TRANSLATED
    (b' = b + (d' - d), outside K) or REFLECTED (b* = b + (d' - d) fell into K, so
    ``b' = b* + 2 u^T (d' - b*) u``, u = (d' - d) / |d' - d|: the mirror image across the plane
    through d' perpendicular to u). Membership is strict (|x - centre| < r), as the gather's."""
    if _dist2(b, d_off) < r * r:
        return b, NULL
    e = _sub(d_off, d)
    bs = (b[0] + e[0], b[1] + e[1], b[2] + e[2])
    if not _dist2(bs, d) < r * r:
        return bs, TRANSLATED
    n = math.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
    u = (e[0] / n, e[1] / n, e[2] / n)        # n > 0 here: with d' = d every b of K is in K'
    k = 2.0 * (u[0] * (d_off[0] - bs[0]) + u[1] * (d_off[1] - bs[1]) + u[2] * (d_off[2] - bs[2]))
    return (bs[0] + k * u[0], bs[1] + k * u[1], bs[2] + k * u[2]), REFLECTED


@leaf
def photon_shift(b, d, d_off, r, mixed):
    """:func:`mixed_shift` if ``mixed``, else :func:`simple_shift` (the integrator's ``shift=``)."""
    if mixed:
        return mixed_shift(b, d, d_off, r)
    return simple_shift(b, d, d_off)


@leaf
def truncated_distance_pdf(sigma, s, t):
    """The density of the camera distance sample t on a beam of length s (Gruson et al. 2018,
    Eq. 14: ``sigma e^(-sigma t) / (1 - e^(-sigma s))``, uniform 1 / s as sigma -> 0, s = inf the plain
    exponential; 0 outside [0, s]): the same density
    :func:`gdlearn.kernels.media.medium.sample_distance_truncated_1` returns with its sample, so the
    MIS ratio of the distance copy, evaluated on the offset's own beam, uses the density the offset
    pixel would have sampled t with (PHOTONS.md E10)."""
    if not (0.0 <= t <= s):
        return 0.0
    if sigma <= 0.0:
        return 1.0 / s if s < math.inf else 0.0
    em = -math.expm1(-sigma * s) if s < math.inf else 1.0
    return sigma * math.exp(-sigma * t) / em
