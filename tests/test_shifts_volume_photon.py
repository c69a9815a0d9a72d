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
