"""Tests of the exercise "bre-kernel". Each docstring is the line `gdlearn check` prints.

Hand values first; then the disc normalisation of K2 (scipy quadrature) and gdlearn's compiled
biweight; the conditions 0 < t < s and d < r; and a brute-force integral of your contribution over
photon positions (a midpoint rule in cylindrical coordinates about a ray in no special direction),
which for a uniform photon density must equal the measurement it estimates, whatever the radius.
"""
import math

import numpy as np
from scipy import integrate

from gdlearn.integrators.photon.volume_estimates import biweight as gdlearn_biweight
from gdlearn.teaching.exercises import load_target

ex = load_target("bre-kernel")

K2_HALF = 3.0 / math.pi * 0.75 ** 2          # K2(0.5) = 3/pi (1 - 1/4)^2


def test_biweight_hand_values():
    """biweight: K2(0) = 3/pi, K2(0.5) = 3/pi * 0.5625, and 0 on and outside the unit circle"""
    assert math.isclose(ex.biweight(0.0), 3.0 / math.pi, rel_tol=1e-12), f"K2(0) = 3/pi = 0.9549, got {ex.biweight(0.0)}"
    assert math.isclose(ex.biweight(0.5), K2_HALF, rel_tol=1e-12), \
        f"K2(0.5) = 3/pi (1 - 0.25)^2 = {K2_HALF:.6f}, got {ex.biweight(0.5)}"
    for x in (1.0, 1.2, 3.0):
        assert ex.biweight(x) == 0.0, f"K2({x}) must be 0 (the kernel has local support), got {ex.biweight(x)}"


def test_biweight_is_normalised_over_the_disc():
    """biweight: int_0^1 K2(x) 2 pi x dx = 1 (the disc's area element x dx dtheta, PHOTONS.md E3)"""
    area = integrate.quad(lambda x: ex.biweight(x) * 2.0 * math.pi * x, 0.0, 1.0, epsabs=0, epsrel=1e-12)[0]
    printed = integrate.quad(lambda x: ex.biweight(x) * 2.0 * math.pi, 0.0, 1.0, epsabs=0, epsrel=1e-12)[0]
    assert math.isclose(area, 1.0, rel_tol=1e-9), \
        f"int_0^1 K2(x) 2 pi x dx = {area:.6f}, must be 1 (against the printed measure dx dtheta it is {printed:.4f}; " \
        "Silverman's K2 is normalised over the disc)"


def test_biweight_agrees_with_gdlearn():
    """biweight: the same values as gdlearn's compiled kernel (volume_estimates.biweight, which takes x^2)"""
    for x in np.linspace(0.0, 1.3, 27):
        mine, theirs = ex.biweight(float(x)), float(gdlearn_biweight(float(x) ** 2))
        assert math.isclose(mine, theirs, rel_tol=1e-12, abs_tol=1e-15), f"K2({x:.3f}): yours {mine}, gdlearn's {theirs}"


def test_contribution_hand_value():
    """bre_contribution: one photon by hand (d / r = 0.5 at t = 1: K2(0.5) / r^2 e^(-sigma_t t) sigma_s p Phi)"""
    got = ex.bre_contribution((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), 2.0, (1.0, 0.05, 0.0), 0.1, 0.5, 0.3, 0.1, 2.0)
    want = K2_HALF / 0.01 * math.exp(-0.5) * 0.3 * 0.1 * 2.0
    assert math.isclose(got, want, rel_tol=1e-9), \
        f"expected K2(0.5) / 0.1^2 * exp(-0.5 * 1) * 0.3 * 0.1 * 2 = {want:.6f}, got {got}"


def test_transmittance_at_the_projected_point():
    """bre_contribution: Tr is taken at the projection t = (x_p - o) . w, not at the photon's distance from o"""
    o, w = (0.0, 0.0, 0.0), (0.0, 0.0, 1.0)
    on_axis = ex.bre_contribution(o, w, 5.0, (0.0, 0.0, 2.0), 0.4, 1.0, 1.0, 1.0, 1.0)
    off_axis = ex.bre_contribution(o, w, 5.0, (0.2, 0.0, 2.0), 0.4, 1.0, 1.0, 1.0, 1.0)
    ratio = off_axis / on_axis if on_axis else float("nan")
    assert on_axis > 0 and math.isclose(ratio, 0.5625, rel_tol=1e-9), \
        f"a photon 0.2 off the axis at t = 2 (r = 0.4) must weigh K2(0.5) / K2(0) = 0.5625 of one on the axis " \
        f"(the same Tr(2): Tr is taken at the projected point); got the ratio {ratio:.6f}"


def test_only_photons_projecting_onto_the_segment_count():
    """bre_contribution: 0 unless 0 < t < s (behind the camera, beyond the surface) and d < r"""
    o, w, s, r = (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), 1.5, 0.2
    for t in (-0.1, -1e-9, s + 1e-9, s + 0.1):
        got = ex.bre_contribution(o, w, s, (0.0, t, 0.0), r, 0.7, 0.4, 0.2, 1.0)
        assert got == 0.0, f"a photon on the axis at t = {t:+.3g} lies outside (0, s = {s}): it must add 0, got {got}"
    assert ex.bre_contribution(o, w, s, (0.0, s - 1e-3, 0.0), r, 0.7, 0.4, 0.2, 1.0) > 0.0, \
        "a photon on the axis just before the surface (t = s - 0.001) must count"
    got = ex.bre_contribution(o, w, s, (0.25, 0.7, 0.0), r, 0.7, 0.4, 0.2, 1.0)
    assert got == 0.0, f"a photon at d = 0.25 > r = {r} from the ray must add 0, got {got}"


def _frame(w):
    """Two unit vectors perpendicular to w and to each other."""
    a = np.array([1.0, 0.0, 0.0]) if abs(w[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(w, a)
    u /= np.linalg.norm(u)
    return u, np.cross(w, u)


def _midpoints(a, b, n):
    h = (b - a) / n
    return a + h * (np.arange(n) + 0.5), h


def _measured(r, o, w, s, sigma_t, sigma_s, phase, power):
    """int contribution(x) dV over photon positions x = o + t w + rho (cos th u + sin th v), by the
    midpoint rule in (t, rho, th) with dV = rho drho dth dt; grids aligned with t = 0, s and rho = r."""
    u, v = _frame(w)
    ts = [_midpoints(-0.3, 0.0, 6), _midpoints(0.0, s, 40), _midpoints(s, s + 0.3, 6)]
    rs = [_midpoints(0.0, r, 40), _midpoints(r, 1.3 * r, 6)]
    ths, hth = _midpoints(0.0, 2.0 * math.pi, 12)
    total = 0.0
    for tt, ht in ts:
        for rr, hr in rs:
            for t in tt:
                for rho in rr:
                    for th in ths:
                        x = o + t * w + rho * (math.cos(th) * u + math.sin(th) * v)
                        f = ex.bre_contribution(tuple(o), tuple(w), s, tuple(x), r, sigma_t, sigma_s, phase, power)
                        total += f * rho * hr * hth * ht
    return total


def test_brute_force_integral_is_the_measurement():
    """brute force: for a uniform photon density your contribution integrates to sigma_s p Phi (1 - e^(-sigma_t s)) / sigma_t, at r = 0.05 and 0.2"""
    o = np.array([0.3, -0.2, 0.5])
    w = np.array([0.48, -0.6, 0.64])
    w /= np.linalg.norm(w)
    s, sigma_t, sigma_s, phase, power = 1.7, 0.8, 0.5, 0.13, 2.5
    want = sigma_s * phase * power * -math.expm1(-sigma_t * s) / sigma_t
    ratios = {r: _measured(r, o, w, s, sigma_t, sigma_s, phase, power) / want for r in (0.05, 0.2)}
    q05, q20 = ratios[0.05], ratios[0.2]
    if all(math.isclose(q, r * r, rel_tol=0.01) for r, q in ratios.items()):
        hint = "the ratio is r^2: the kernel misses its 1 / r^2"
    elif math.isclose(q05 * 0.05, q20 * 0.2, rel_tol=0.01):
        hint = "the ratio falls as 1 / r: the kernel is normalised as a 3D one (1 / r^3), not over the disc"
    elif math.isclose(q05, q20, rel_tol=0.01):
        hint = "the ratio does not depend on r but is not 1: K2 or one of the factors is scaled wrongly"
    else:
        hint = "check t (the projection), d (the perpendicular distance) and Tr(t)"
    for r, q in ratios.items():
        assert abs(q - 1.0) < 5e-3, \
            f"r = {r}: int contribution dV = {q * want:.6g}, the measurement is {want:.6g} (ratio {q:.4f}); {hint}"
