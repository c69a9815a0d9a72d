"""The kernel-vertex shifts of gradient-domain volumetric photon mapping (Gruson et al. 2018, Sec. 4.1-4.2;
PHOTONS.md Sec. 5.2-5.3).

A G-VPM path merges a light subpath ending at the photon b (parent a) with a camera subpath whose
last edge, the camera beam from c, holds the gather point d = c + t w_c. Shifting the pixel moves the
camera beam to c' + t w'_c; the kernel vertices follow (Gruson et al. 2018, Eq. 13: the Jacobian
separates into ``|db'/db|`` ``|dd'/dd|``):

* **camera distance copy** (Sec. 4.1, Eq. 14-15): d' = c' + t w'_c, the same distance t on the
  offset's beam. In the (direction, distance) parametrisation of a volume point the distance part of
  the Jacobian is dt'/dt = 1 (``gdlearn.shifts.distance.JACOBIAN``). The shift fails where
  the offset's beam is shorter than t (:func:`camera_distance_copy`); the region of a longer offset
  beam that no base reaches is the reverse shift's failure, so the pair stays unbiased.
* **photon shifts** (Sec. 4.2, Eq. 16), K = Ball(d, r), K' = Ball(d', r), u = (d' - d) / ``|d' - d|``:

  - *simple*: b' = b + (d' - d), a translation (:func:`simple_shift`);
  - *null*: b' = b, free, but only the photons already in K' are reachable;
  - *mixed* (Eq. 16): null if b is in K'; otherwise b* = b + (d' - d), and if b* fell into K (the
    overlap, already covered by the null part) it is reflected across the plane through d'
    perpendicular to u, ``b' = b* + 2 u^T (d' - b*) u`` (:func:`mixed_shift`).

  The mixed shift is a bijection K -> K' with ``|J|`` = 1 (PHOTONS.md Sec. 5.3): the translation maps
  K \\ K' onto K' \\ K'' (K'' = Ball(d' + D u, r)); the reflection R' across the plane through d'
  maps K' onto itself and K' \\ K'' onto K' \\ K, so the translated pieces that land in K are moved
  onto exactly the part of K' \\ K the translation missed. Its inverse is the same construction
  from the offset pixel (d' -> d), which returns b exactly (tests/test_shifts_volume_photon.py).
  Translations and reflections preserve volume, hence ``|db'/db|`` = 1 (:data:`PHOTON_JACOBIAN`).

Everything here is a pure function of 3-vectors (tuples), callable from numba and from Python.
"""
import math

from gdlearn.kernels.jit import leaf

#: ``|db'/db|`` of the simple and the mixed shift (translation, reflection: volume preserving)
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
    ``b' = b* + 2 u^T (d' - b*) u``, u = (d' - d) / ``|d' - d|``: the mirror image across the plane
    through d' perpendicular to u). Membership is strict (``|x - centre|`` < r), as the gather's."""
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


#: ray_frame_copy refuses rays closer to antiparallel than this (1 + w . w'): the rotation's axis is
#: undefined there; neighbouring pixels' rays never come near it, so it only guards the division
ANTIPARALLEL = 1e-9


@leaf
def ray_frame_rotation(w, w_off):
    """The rotation R with R w = w' that turns least -- about w x w' by the angle between them
    (Rodrigues, ``R = c I + [v]x + v v^T / (1 + c)``, v = w x w', c = w . w'; stable as c -> 1, no
    cancellation). It carries a frame around the base ray onto one around the offset ray by parallel
    transport, continuous in both directions for every ray orientation (a frame built from each
    direction alone, Duff et al.'s ONB, jumps where n_z changes sign; PHOTONS.md Sec. 7, "frames").
    The rotation from w' back to w is exactly R^T (v changes sign, c does not), so the G-BRE-2D
    shift and its reverse are inverses. Returns ``(ok, rows of R)``; not ok for (near-)antiparallel rays."""
    c = w[0] * w_off[0] + w[1] * w_off[1] + w[2] * w_off[2]
    v = (w[1] * w_off[2] - w[2] * w_off[1], w[2] * w_off[0] - w[0] * w_off[2], w[0] * w_off[1] - w[1] * w_off[0])
    eye = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    if not 1.0 + c > ANTIPARALLEL:
        return False, eye
    k = 1.0 / (1.0 + c)
    return True, ((c + k * v[0] * v[0], -v[2] + k * v[0] * v[1], v[1] + k * v[0] * v[2]),
                  (v[2] + k * v[1] * v[0], c + k * v[1] * v[1], -v[0] + k * v[1] * v[2]),
                  (-v[1] + k * v[2] * v[0], v[0] + k * v[2] * v[1], c + k * v[2] * v[2]))


@leaf
def ray_frame_copy(b, d, w, d_off, w_off):
    """The G-BRE-2D photon shift (Gruson et al. 2018, Sec. 5.1, Fig. 6d; PHOTONS.md Sec. 5.6): the
    photon b, seen from its gather point d (its projection on the base camera ray of direction w), is
    copied rigidly into the offset ray's frame, ``b' = d' + R (b - d)`` with R of
    :func:`ray_frame_rotation` and d' = c' + t w' the distance copy of d. R w = w' and R preserves
    lengths, so d' b' is perpendicular to the offset ray, ``|d' b'| = |d b|`` (the 2D kernel has the
    same value at both), and b' projects onto the offset ray at the same t. A rotation and a
    translation: ``|db'/db| = 1`` (:data:`PHOTON_JACOBIAN`). Returns ``(ok, b')``."""
    ok, rot = ray_frame_rotation(w, w_off)
    e = _sub(b, d)
    out = (d_off[0] + rot[0][0] * e[0] + rot[0][1] * e[1] + rot[0][2] * e[2],
           d_off[1] + rot[1][0] * e[0] + rot[1][1] * e[1] + rot[1][2] * e[2],
           d_off[2] + rot[2][0] * e[0] + rot[2][1] * e[1] + rot[2][2] * e[2])
    return ok, out


@leaf
def ray_frame_copy_inverse(b_off, d, w, d_off, w_off):
    """The inverse of :func:`ray_frame_copy` (the reverse shift, from the offset ray back to the base
    one): ``b = d + R^T (b' - d')``, which is the same copy with the two frames swapped."""
    return ray_frame_copy(b_off, d_off, w_off, d, w)


@leaf
def chord_half(r, dperp2):
    """Half the chord a ray cuts through a ball of radius r whose centre lies dperp2 (squared) from
    it: sqrt(r^2 - d_perp^2), 0 outside. The uniform density of a BRE-3D gather point on that chord
    is 1 / (2 half) (Gruson et al. 2018, Sec. 5.1, "Point-Beam 3D"; PHOTONS.md Sec. 3.7)."""
    q = r * r - dperp2
    return math.sqrt(q) if q > 0.0 else 0.0
