"""Warps and MIS heuristics (gdlearn.kernels.sampling): chi^2 goodness of fit against the textbook
densities, pdf consistency, and MIS weights at extreme pdfs."""
import math

import numpy as np
import pytest
from numba import njit

from gdlearn.kernels import sampling as S
from test_kernels_helpers import chi2_pvalue, sphere_bins, sphere_grid

N = 100_000
ALPHA = 1e-3       # per-test significance; seeds are fixed so the outcome is deterministic


@njit(cache=True)
def _warp_many(kind, u, cos_max):
    out = np.empty((u.shape[0], 3))
    pdf = np.empty(u.shape[0])
    for i in range(u.shape[0]):
        if kind == 0:
            w = S.square_to_cosine_hemisphere(u[i, 0], u[i, 1])
            p = S.cosine_hemisphere_pdf(w)
        elif kind == 1:
            w = S.square_to_uniform_sphere(u[i, 0], u[i, 1])
            p = S.uniform_sphere_pdf()
        elif kind == 2:
            w = S.square_to_uniform_hemisphere(u[i, 0], u[i, 1])
            p = S.uniform_hemisphere_pdf(w)
        else:
            w = S.square_to_uniform_cone(u[i, 0], u[i, 1], cos_max)
            p = S.uniform_cone_pdf(w, cos_max)
        out[i, 0], out[i, 1], out[i, 2] = w
        pdf[i] = p
    return out, pdf


def _uniform(seed, n=N):
    return np.random.default_rng(seed).random((n, 2))


# independent truths (textbook densities, not the code under test)
TRUTH = {
    0: lambda d: np.where(d[:, 2] > 0, d[:, 2] / np.pi, 0.0),
    1: lambda d: np.full(len(d), 1 / (4 * np.pi)),
    2: lambda d: np.where(d[:, 2] > 0, 1 / (2 * np.pi), 0.0),
}


@pytest.mark.parametrize("kind", [0, 1, 2])
def test_direction_warps_chi2(kind):
    dirs, pdf = _warp_many(kind, _uniform(10 + kind), 0.0)
    assert np.allclose(np.linalg.norm(dirs, axis=1), 1.0, atol=1e-12)
    n_cos, n_phi = 20, 40
    obs = sphere_bins(dirs, n_cos, n_phi)
    q, w = sphere_grid(n_cos, n_phi, 6)
    exp = (TRUTH[kind](q) * w).reshape(n_cos, n_phi, -1).sum(-1) * N
    assert chi2_pvalue(obs, exp) > ALPHA
    # the reported pdf is the true density at the sampled direction (to rounding)
    assert np.allclose(pdf, TRUTH[kind](dirs), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("cos_max", [0.5, 0.999])
def test_cone_chi2(cos_max):
    """Bins in ((1 - cos) / (1 - cos_max), phi): the uniform cone is uniform there."""
    dirs, pdf = _warp_many(3, _uniform(21), cos_max)
    assert np.all(dirs[:, 2] >= cos_max - 1e-15)
    v = (1.0 - dirs[:, 2]) / (1.0 - cos_max)
    phi = np.mod(np.arctan2(dirs[:, 1], dirs[:, 0]), 2 * np.pi)
    obs, _, _ = np.histogram2d(v, phi, bins=[10, 20], range=[[0, 1], [0, 2 * np.pi]])
    assert chi2_pvalue(obs, np.full(obs.shape, N / 200)) > ALPHA
    assert np.allclose(pdf, 1.0 / (2 * np.pi * (1.0 - cos_max)), rtol=1e-12)


def test_cone_is_not_uniform_in_cos_when_wrong():
    """The chi^2 machinery can fail: cosine-hemisphere samples are rejected as a uniform cone."""
    dirs, _ = _warp_many(0, _uniform(22), 0.0)
    v = 1.0 - dirs[:, 2]
    phi = np.mod(np.arctan2(dirs[:, 1], dirs[:, 0]), 2 * np.pi)
    obs, _, _ = np.histogram2d(v, phi, bins=[10, 20], range=[[0, 1], [0, 2 * np.pi]])
    assert chi2_pvalue(obs, np.full(obs.shape, N / 200)) < 1e-6


@njit(cache=True)
def _tri_many(u):
    out = np.empty((u.shape[0], 2))
    for i in range(u.shape[0]):
        out[i, 0], out[i, 1] = S.square_to_uniform_triangle(u[i, 0], u[i, 1])
    return out


def test_triangle_chi2():
    """Barycentrics (b1, b2) are uniform on {b1, b2 >= 0, b1 + b2 <= 1}: with an n x n grid the
    diagonal passes through bin corners, so a bin holds area h^2, h^2 / 2 or 0 exactly."""
    b = _tri_many(_uniform(31))
    assert np.all(b >= 0) and np.all(b.sum(1) <= 1 + 1e-15)
    n = 16
    obs, _, _ = np.histogram2d(b[:, 0], b[:, 1], bins=[n, n], range=[[0, 1], [0, 1]])
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    area = np.where(i + j < n - 1, 1.0, np.where(i + j == n - 1, 0.5, 0.0)) / n**2
    assert chi2_pvalue(obs, area * 2.0 * N) > ALPHA


@njit(cache=True)
def _disk_many(u):
    out = np.empty((u.shape[0], 2))
    for i in range(u.shape[0]):
        out[i, 0], out[i, 1] = S.square_to_uniform_disk_concentric(u[i, 0], u[i, 1])
    return out


def test_concentric_disk_chi2():
    """Uniform on the unit disk <=> (r^2, phi) uniform on [0,1] x [0, 2 pi)."""
    p = _disk_many(_uniform(41))
    r2 = (p**2).sum(1)
    assert np.all(r2 <= 1 + 1e-12)
    phi = np.mod(np.arctan2(p[:, 1], p[:, 0]), 2 * np.pi)
    obs, _, _ = np.histogram2d(r2, phi, bins=[10, 20], range=[[0, 1], [0, 2 * np.pi]])
    assert chi2_pvalue(obs, np.full(obs.shape, N / 200)) > ALPHA


def test_mis_heuristics_extremes():
    for h in (S.power_heuristic, S.balance_heuristic):
        assert h(1e300, 1e-300) == 1.0
        assert h(1e-300, 1e300) == 0.0
        assert h(1e-300, 1e-300) == pytest.approx(0.5)
        assert h(1e300, 1e300) == pytest.approx(0.5)
        assert h(0.0, 1.0) == 0.0 and h(1.0, 0.0) == 1.0 and h(0.0, 0.0) == 0.0
        assert math.isfinite(h(1e-310, 1e308))
    rng = np.random.default_rng(5)
    for a, b in 10.0 ** rng.uniform(-300, 300, size=(500, 2)):
        wa, wb = S.power_heuristic(a, b), S.power_heuristic(b, a)
        assert 0.0 <= wa <= 1.0 and abs(wa + wb - 1.0) < 1e-12
        ba, bb = S.balance_heuristic(a, b), S.balance_heuristic(b, a)
        assert abs(ba + bb - 1.0) < 1e-12


def test_mis_heuristics_moderate_values_match_textbook():
    rng = np.random.default_rng(6)
    for a, b in rng.uniform(0.01, 10.0, size=(200, 2)):
        assert S.power_heuristic(a, b) == pytest.approx(a * a / (a * a + b * b), rel=1e-12)
        assert S.balance_heuristic(a, b) == pytest.approx(a / (a + b), rel=1e-12)


def test_sincos_quarter_matches_libm_to_an_ulp_or_two():
    a = np.concatenate([np.linspace(-math.pi / 4, math.pi / 4, 20001), [0.0, 1e-300, -1e-8, math.pi / 4]])
    for x in a:
        s, c = S.sincos_quarter(x)
        assert abs(s - math.sin(x)) <= 2.5e-16 * abs(math.sin(x)) + 1e-320
        assert abs(c - math.cos(x)) <= 2.5e-16 * math.cos(x)


def test_uniform_unit_circle_is_the_shifted_angle():
    """(cos, sin) of phi = 2 pi u - pi/4 to ~1 ulp of the unit circle's coordinates, every quadrant
    and its boundaries included (the quadrant is chosen by arithmetic signs: a wrong sign or swap
    would be off by O(1))."""
    u = np.concatenate([np.random.default_rng(10).random(20000), [0.0, 0.25, 0.5, 0.75, 1 - 2**-53],
                        np.nextafter([0.25, 0.5, 0.75], 0.0)])
    for x in u:
        c, s = S.uniform_unit_circle(x)
        phi = 2 * math.pi * x - math.pi / 4
        # 2e-15: the reference's own rounding of phi (|phi| < 6, ulp 9e-16) dominates
        assert abs(c - math.cos(phi)) <= 2e-15 and abs(s - math.sin(phi)) <= 2e-15
        assert abs(math.hypot(c, s) - 1.0) <= 4.5e-16


def test_concentric_disk_is_mitsubas_formula():
    """The same (u1, u2) gives Mitsuba's point (warp.h, written here with libm's sin and cos)."""
    for u1, u2 in np.random.default_rng(9).random((5000, 2)):
        x, y = 2 * u1 - 1, 2 * u2 - 1
        if abs(x) > abs(y):
            r, phi = x, math.pi / 4 * (y / x)
        else:
            r, phi = y, math.pi / 2 - math.pi / 4 * (x / y)
        assert S.square_to_uniform_disk_concentric(u1, u2) == pytest.approx((r * math.cos(phi), r * math.sin(phi)),
                                                                            abs=1e-15)
