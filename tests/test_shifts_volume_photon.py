"""The kernel-vertex shifts of G-VPM (Gruson et al. 2018, Sec. 4.1-4.2, Eq. 14-16; PHOTONS.md T1):
the mixed shift is a volume-preserving bijection Ball(d, r) -> Ball(d', r) whose reverse (from d'
to d) returns the photon, the null part is exactly the overlap, no overlap means a translation;
the camera distance copy and the truncated-exponential density its MIS uses."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from gdlearn.shifts import volume_photon as V

R = 0.37
D0 = np.array([0.2, -1.1, 0.4])
N = 20_000


def _ball(rng, n, r=R):
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1)[:, None]
    return v * (r * rng.uniform(size=n) ** (1.0 / 3.0))[:, None]


def _setup(sep, seed):
    rng = np.random.default_rng(seed)
    u = rng.normal(size=3)
    u /= np.linalg.norm(u)
    d2 = D0 + sep * R * u
    return rng, u, d2


def _shift_all(b, d, d2, r=R):
    out = np.empty_like(b)
    kinds = np.empty(len(b), int)
    for i, p in enumerate(b):
        q, k = V.mixed_shift(tuple(p), tuple(d), tuple(d2), r)
        out[i] = q
        kinds[i] = k
    return out, kinds


def _lens_fraction(sep):
    """Volume of Ball(d, r) and Ball(d', r) overlapping, over the ball's, at |d' - d| = sep r."""
    if sep >= 2.0:
        return 0.0
    return (4.0 + sep) * (2.0 - sep) ** 2 / 16.0


@pytest.mark.parametrize("sep", [1e-9, 0.05, 0.6, 1.0, 1.7, 1.999])
def test_mixed_shift_is_a_bijection_into_the_offset_kernel(sep):
    """b uniform in K: b' lies in K', the reverse mixed shift (d' -> d) gives b back to 1e-12, the
    null photons are exactly the overlap (binomial, 5 sigma), and the points b' are uniform on K'
    (chi-square over 100 equal-volume cells: radial shells x polar bands about u x azimuth; p >
    1e-4, so a correct shift fails it once in 10^4 runs). Reflecting across the plane through d
    instead of d' puts b' outside K'; translating without the reflection piles two preimages
    on the overlap (chi-square p ~ 0)."""
    rng, u, d2 = _setup(sep, seed=int(sep * 1000) + 1)
    b = D0 + _ball(rng, N)
    b2, kinds = _shift_all(b, D0, d2)
    assert np.all(np.linalg.norm(b2 - d2, axis=1) < R * (1 + 1e-12)), "b' outside K'"
    back, kinds_back = _shift_all(b2, d2, D0)
    assert np.abs(back - b).max() < 1e-12 * max(1.0, np.abs(b).max())
    assert np.array_equal(kinds, kinds_back), "the reverse shift takes another branch"
    p_null = _lens_fraction(sep)
    n_null = (kinds == V.NULL).sum()
    assert abs(n_null - N * p_null) <= 5 * math.sqrt(N * p_null * (1 - p_null)) + 1
    # equal-volume cells of the ball around d', axis u (uniform: r^3, cos(polar), azimuth all uniform)
    e = (b2 - d2) / R
    rad = np.linalg.norm(e, axis=1)
    cos_p = np.clip(e @ u / np.maximum(rad, 1e-300), -1, 1)
    s = np.cross(u, [1.0, 0.0, 0.0] if abs(u[0]) < 0.9 else [0.0, 1.0, 0.0])
    s /= np.linalg.norm(s)
    t = np.cross(u, s)
    az = np.arctan2(e @ t, e @ s)
    i = np.minimum((rad ** 3 * 5).astype(int), 4)
    j = np.minimum(((cos_p + 1) / 2 * 5).astype(int), 4)
    k = np.minimum(((az + math.pi) / (2 * math.pi) * 4).astype(int), 3)
    counts = np.bincount((i * 5 + j) * 4 + k, minlength=100)
    chi2 = ((counts - N / 100) ** 2 / (N / 100)).sum()
    assert stats.chi2.sf(chi2, 99) > 1e-4, f"b' not uniform on K': chi2 {chi2:.0f} on 99 dof"


def test_no_overlap_is_a_pure_translation():
    """|d' - d| >= 2r: the supports do not meet, every photon is translated by d' - d."""
    rng, u, d2 = _setup(2.5, seed=7)
    b = D0 + _ball(rng, 2000)
    b2, kinds = _shift_all(b, D0, d2)
    assert np.all(kinds == V.TRANSLATED)
    assert np.abs(b2 - (b + (d2 - D0))).max() < 1e-15


def test_d_prime_equal_to_d_keeps_every_photon():
    rng = np.random.default_rng(2)
    b = D0 + _ball(rng, 500)
    b2, kinds = _shift_all(b, D0, D0)
    assert np.all(kinds == V.NULL) and np.array_equal(b2, b)


def test_simple_shift_is_the_translation():
    b, d, d2 = (0.1, 0.2, 0.3), (0.0, 0.0, 0.0), (0.5, -0.25, 0.0)
    q, k = V.simple_shift(b, d, d2)
    assert np.allclose(q, (0.6, -0.05, 0.3), rtol=0, atol=1e-15) and k == V.TRANSLATED
    assert V.photon_shift(b, d, d2, 1.0, True) == V.mixed_shift(b, d, d2, 1.0)
    assert V.photon_shift(b, d, d2, 1.0, False) == (q, k)


def test_camera_distance_copy():
    """t' = t with Jacobian 1 where the offset beam reaches t; a failure where it is shorter."""
    assert V.camera_distance_copy(1.5, 2.0) == (True, 1.5, 1.0)
    assert V.camera_distance_copy(1.5, math.inf) == (True, 1.5, 1.0)
    assert V.camera_distance_copy(2.5, 2.0)[0] is False


@pytest.mark.parametrize("sigma,s", [(0.2, 3.0), (5.0, 0.7), (1e-9, 2.0), (0.0, 2.0), (0.3, math.inf)])
def test_truncated_distance_pdf_is_the_sampling_density(sigma, s):
    """It integrates to one on [0, s] and equals the pdf sample_distance_truncated_1 returns."""
    from scipy.integrate import quad
    from gdlearn.kernels.media.medium import sample_distance_truncated_1
    area = quad(lambda t: V.truncated_distance_pdf(sigma, s, t), 0.0, s, limit=200)[0] if s < math.inf else \
        quad(lambda t: V.truncated_distance_pdf(sigma, s, t), 0.0, math.inf)[0]
    assert area == pytest.approx(1.0, rel=1e-7)
    for uu in (0.1, 0.5, 0.93):
        t, pdf = sample_distance_truncated_1(sigma, s, uu)
        assert V.truncated_distance_pdf(sigma, s, t) == pytest.approx(pdf, rel=1e-12)
    assert V.truncated_distance_pdf(sigma, s, -0.1) == 0.0


# -- G-BRE-2D: the rigid ray-frame copy (Gruson et al. 2018, Sec. 5.1, Fig. 6d) ------------------------

def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


#: base / offset ray directions: random pairs one pixel apart, and the near-degenerate ones -- equal,
#: 1e-12 apart, along +-z (where an ONB built from each direction alone, Duff et al.'s, flips its
#: tangent), straddling z = 0 (the other place such an ONB jumps), 90 and 170 degrees apart
_PAIRS = [(_unit([0.3, -0.2, -1.0]), _unit([0.31, -0.2, -1.0])), (_unit([0, 0, 1.0]), _unit([0, 0, 1.0])),
          (_unit([0, 0, -1.0]), _unit([1e-12, 0, -1.0])), (_unit([0, 0, -1.0]), _unit([0.02, 0.01, -1.0])),
          (_unit([1.0, 0.5, 1e-9]), _unit([1.0, 0.5, -1e-9])), (_unit([0.2, 1.0, 0.0]), _unit([0.2, 1.0, 0.003])),
          (_unit([1.0, 0, 0]), _unit([0, 1.0, 0])), (_unit([1.0, 0, 0]), _unit([-1.0, 0.17, 0]))]


def _frame_pair(rng, w, w2, t=1.7):
    c, c2 = rng.normal(size=3), rng.normal(size=3)
    return c + t * w, c2 + t * w2


@pytest.mark.parametrize("k", range(len(_PAIRS)))
def test_ray_frame_copy_is_rigid_and_keeps_the_perpendicular_offset(k):
    """b' - d' is perpendicular to the offset ray with |b' - d'| = |b - d| (the 2D kernel's value is the
    same at both gather points) when b - d is perpendicular to the base ray; the copy of a point on the
    base ray lands on the offset ray; w -> w' is exact (R w = w'); R is a rotation (R^T R = I, det 1)."""
    rng = np.random.default_rng(40 + k)
    w, w2 = _PAIRS[k]
    d, d2 = _frame_pair(rng, w, w2)
    ok, rot = V.ray_frame_rotation(tuple(w), tuple(w2))
    rot = np.array(rot)
    assert ok
    assert np.allclose(rot @ w, w2, atol=1e-14) and np.allclose(rot.T @ rot, np.eye(3), atol=1e-14)
    assert np.linalg.det(rot) == pytest.approx(1.0, abs=1e-13)
    for _ in range(20):
        e = rng.normal(size=3)
        e -= (e @ w) * w                          # the photon's offset from its projection d
        ok, b2 = V.ray_frame_copy(tuple(d + e), tuple(d), tuple(w), tuple(d2), tuple(w2))
        e2 = np.array(b2) - d2
        assert ok and abs(e2 @ w2) < 1e-12 and np.linalg.norm(e2) == pytest.approx(np.linalg.norm(e), rel=1e-13)
    ok, b2 = V.ray_frame_copy(tuple(d + 0.4 * w), tuple(d), tuple(w), tuple(d2), tuple(w2))
    assert np.allclose(b2, d2 + 0.4 * w2, atol=1e-13)


@pytest.mark.parametrize("k", range(len(_PAIRS)))
def test_ray_frame_copy_inverse_round_trip(k):
    """The inverse map (the reverse shift, from the offset ray to the base ray) returns b to 1e-12,
    also for the near-degenerate directions of _PAIRS; a frame built from each ray's direction alone
    would pass this too, so the continuity is checked separately."""
    rng = np.random.default_rng(70 + k)
    w, w2 = _PAIRS[k]
    d, d2 = _frame_pair(rng, w, w2)
    for _ in range(50):
        b = d + rng.normal(size=3) * 0.3
        ok, b2 = V.ray_frame_copy(tuple(b), tuple(d), tuple(w), tuple(d2), tuple(w2))
        ok2, back = V.ray_frame_copy_inverse(b2, tuple(d), tuple(w), tuple(d2), tuple(w2))
        assert ok and ok2 and np.allclose(back, b, rtol=0, atol=1e-12)


@pytest.mark.parametrize("k", range(len(_PAIRS)))
def test_ray_frame_copy_jacobian_by_finite_differences(k):
    """|db'/db| = 1 (PHOTON_JACOBIAN): the central-difference Jacobian of the map (h = 1e-6, error
    O(h^2) on an affine map, i.e. rounding only) has determinant 1 to 1e-8."""
    rng = np.random.default_rng(90 + k)
    w, w2 = _PAIRS[k]
    d, d2 = _frame_pair(rng, w, w2)
    b = d + rng.normal(size=3) * 0.2
    h = 1e-6
    jac = np.empty((3, 3))
    for i in range(3):
        e = np.zeros(3)
        e[i] = h
        p = np.array(V.ray_frame_copy(tuple(b + e), tuple(d), tuple(w), tuple(d2), tuple(w2))[1])
        m = np.array(V.ray_frame_copy(tuple(b - e), tuple(d), tuple(w), tuple(d2), tuple(w2))[1])
        jac[:, i] = (p - m) / (2 * h)
    assert abs(np.linalg.det(jac)) == pytest.approx(V.PHOTON_JACOBIAN, abs=1e-8)


def test_ray_frame_copy_is_continuous_in_the_ray_directions():
    """Sweeping the offset direction through z = 0 and past +-z (where a per-direction ONB jumps by a
    quarter turn or more), the copied photon moves by O(step): the frame is parallel-transported.
    Antiparallel rays are refused (the axis is undefined), not answered with garbage."""
    d = np.zeros(3)
    b = np.array([0.3, -0.1, 0.2])
    for w in (_unit([1.0, 0.2, 0.0]), _unit([0.0, 0.05, -1.0])):
        prev = None
        for a in np.linspace(-0.02, 0.02, 401):
            w2 = _unit(w + a * np.array([0.3, -0.5, 1.0]))
            ok, b2 = V.ray_frame_copy(tuple(b), tuple(d), tuple(w), tuple(d), tuple(w2))
            assert ok
            if prev is not None:
                assert np.linalg.norm(np.array(b2) - prev) < 1e-3        # step 1e-4 in direction
            prev = np.array(b2)
    ok, _ = V.ray_frame_copy(tuple(b), tuple(d), (0.0, 0.0, 1.0), tuple(d), (0.0, 0.0, -1.0))
    assert not ok


def test_chord_half():
    assert V.chord_half(0.5, 0.09) == pytest.approx(0.4, rel=1e-15)
    assert V.chord_half(0.5, 0.25) == 0.0 and V.chord_half(0.5, 0.3) == 0.0
