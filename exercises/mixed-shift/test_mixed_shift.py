"""Tests of the exercise "mixed-shift". Each docstring is the line `gdlearn check` prints.

Hand values first, one per branch; then the three properties of Eq. 16 on a cloud of photons drawn
uniformly in K (images in K', the reverse shift returns b, the images are uniform over K'), and
gdlearn's compiled version. All randomness is seeded.
"""
import numpy as np
from scipy import stats

from gdlearn.shifts.volume_photon import NULL, REFLECTED, TRANSLATED
from gdlearn.shifts.volume_photon import mixed_shift as gdlearn_mixed_shift
from gdlearn.teaching.exercises import load_target

ex = load_target("mixed-shift")

BRANCHES = {NULL: "null", TRANSLATED: "translated", REFLECTED: "reflected"}
D, D_OFF, R = (0.0, 0.0, 0.0), (0.8, 0.0, 0.0), 1.0


def shift(b, d=D, d_off=D_OFF, r=R):
    out = ex.mixed_shift(tuple(map(float, b)), tuple(map(float, d)), tuple(map(float, d_off)), float(r))
    assert len(out) == 2, "mixed_shift returns (b_off, branch)"
    b_off, branch = out
    assert len(b_off) == 3, "b_off is a point (3 numbers)"
    return np.array(b_off, dtype=float), branch


def cloud(n=3000, seed=4, d=D, r=R):
    """n photons uniform in Ball(d, r), and a random pair of centres is used by the callers."""
    rng = np.random.default_rng(seed)
    p = rng.normal(size=(n, 3))
    p *= (r * rng.random(n) ** (1 / 3) / np.linalg.norm(p, axis=1))[:, None]
    return p + np.array(d)


def diagnose(b, d, d_off, got):
    """Which slip produced ``got`` for a photon whose translate must be reflected (empty if none known)."""
    b, d, d_off = (np.array(v, float) for v in (b, d, d_off))
    bs, u = b + d_off - d, (d_off - d) / np.linalg.norm(d_off - d)
    if np.allclose(got, bs, atol=1e-9):
        return (" -- that is b* itself: the reflection is missing (it applies when b* lies in K; b* is"
                " always in K', so a test 'b* outside K'' never fires)")
    if np.allclose(got, bs + 2 * np.dot(u, d - bs) * u, atol=1e-9):
        return " -- that is b* reflected across the plane through d: the plane passes through d'"
    return ""


def test_null_by_hand():
    """by hand: a photon already in K' is kept (the null branch), b' = b"""
    got, branch = shift((0.5, 0.3, 0.0))
    assert np.allclose(got, (0.5, 0.3, 0.0), atol=1e-12) and branch == "null", \
        f"b = (0.5, 0.3, 0), |b - d'| = 0.42 < r: expected ((0.5, 0.3, 0), 'null'), got ({np.round(got, 6)}, {branch!r})"


def test_translated_by_hand():
    """by hand: a photon whose translate b* leaves K is translated, b' = b + (d' - d)"""
    got, branch = shift((-0.3, 0.9, 0.0))
    want = np.array([0.5, 0.9, 0.0])
    assert np.allclose(got, want, atol=1e-12) and branch == "translated", \
        f"b = (-0.3, 0.9, 0): b* = {want} lies outside K; expected (b*, 'translated'), got ({np.round(got, 6)}, {branch!r})"


def test_reflected_by_hand():
    """by hand: a photon whose translate b* falls into K is reflected across the plane through d' (Eq. 16)"""
    b = (-0.5, 0.2, 0.1)
    got, branch = shift(b)
    want = np.array([1.3, 0.2, 0.1])           # b* = (0.3, 0.2, 0.1) mirrored across x = 0.8
    assert np.allclose(got, want, atol=1e-12) and branch == "reflected", \
        (f"b = {b}: b* = (0.3, 0.2, 0.1) lies in K, so b' = b* + 2 u^T (d' - b*) u = {want} ('reflected'); got "
         f"({np.round(got, 6)}, {branch!r}){diagnose(b, D, D_OFF, got)}")


def test_images_lie_in_the_offset_ball():
    """every image b' of a photon of K lies in K' = Ball(d', r)"""
    d, d_off = np.array([0.2, -0.1, 0.3]), np.array([0.5, 0.3, -0.2])
    pts = cloud(d=d, r=0.7)
    for b in pts:
        got, _ = shift(b, d, d_off, 0.7)
        dist = np.linalg.norm(got - d_off)
        assert dist < 0.7 + 1e-12, \
            f"b = {np.round(b, 4)} went to b' = {np.round(got, 4)}, {dist:.4f} from d' (r = 0.7){diagnose(b, d, d_off, got)}"


def test_reverse_shift_returns_the_photon():
    """the same construction from the offset side (d' -> d) returns every photon: the shift is invertible"""
    d, d_off = np.array([0.2, -0.1, 0.3]), np.array([0.5, 0.3, -0.2])
    for b in cloud(seed=7, d=d, r=0.7):
        there, _ = shift(b, d, d_off, 0.7)
        back, _ = shift(there, d_off, d, 0.7)
        assert np.allclose(back, b, atol=1e-9), \
            (f"b = {np.round(b, 4)} -> b' = {np.round(there, 4)} -> back {np.round(back, 4)}: two photons of K share an "
             "image, or one of K' has none -- the map is not a bijection")


def test_images_are_uniform():
    """the images of photons drawn uniformly in K are uniform over K' (radius^3 and the coordinate along u, KS tests)"""
    pts = cloud(n=6000, seed=9)
    rel = np.array([shift(b)[0] for b in pts]) - np.array(D_OFF)
    radial = stats.kstest(np.minimum(np.linalg.norm(rel, axis=1) / R, 1.0) ** 3, "uniform").pvalue
    axial = stats.kstest(np.clip(rel[:, 0] / R, -1, 1), lambda x: (2 + 3 * x - x ** 3) / 4).pvalue
    assert min(radial, axial) > 1e-3, \
        (f"KS p-values: |b' - d'|^3 / r^3 uniform {radial:.1e}, coordinate along u {axial:.1e}: the images crowd part of "
         "K' and leave another empty (a uniform ball gives p-values spread over [0, 1])")


def test_agrees_with_gdlearn():
    """the same b' and branch as gdlearn's compiled version (gdlearn.shifts.volume_photon.mixed_shift)"""
    rng = np.random.default_rng(12)
    for _ in range(200):
        d, d_off = rng.normal(size=3), rng.normal(size=3)
        r = float(rng.uniform(0.6, 2.0))
        b = cloud(n=1, seed=int(rng.integers(1 << 30)), d=d, r=r)[0]
        mine, branch = shift(b, d, d_off, r)
        theirs, kind = gdlearn_mixed_shift(tuple(b), tuple(d), tuple(d_off), r)
        assert np.allclose(mine, theirs, atol=1e-10) and branch == BRANCHES[kind], \
            f"b = {np.round(b, 4)}: yours ({np.round(mine, 6)}, {branch!r}), gdlearn's ({np.round(theirs, 6)}, {BRANCHES[kind]!r})"
