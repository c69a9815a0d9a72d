"""Tests of the exercise "halfvector-mirror". Each docstring is the line `gdlearn check` prints.

Reference values are computed here independently of gdlearn: by hand, from the definition of the
half vector, and by finite differences of the shift map itself (perturb wo_b on the unit sphere,
re-run your shift, measure how far wo_o moved). All randomness is seeded.
"""
import math

import numpy as np
import pytest

from gdlearn.teaching.exercises import load_target
from gdlearn.testing.fdjac import H, fd_determinant, unit
from gdlearn.testing.fdjac import tangent_frame as frame

ex = load_target("halfvector-mirror")

#: Finite-difference step (radians): fourth-order central differences, error ~h^4 |f^(5)| + eps/h
#: ~ 1e-10 for these smooth maps, so 1e-6 relative agreement is demanded; a missing or inverted
#: Jacobian is off by O(1) on most configurations (the test checks it has that power).
REL = 1e-6




def sph(theta_deg, phi_deg=0.0):
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return (math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t))


def copy(wi_b, wo_b, wi_o):
    out = ex.halfvector_copy_mirror(tuple(map(float, wi_b)), tuple(map(float, wo_b)), tuple(map(float, wi_o)))
    assert isinstance(out, tuple) and len(out) == 3, "return (wo_o, jacobian, ok)"
    wo, j, ok = out
    return np.asarray(wo, float), float(j), bool(ok)


def configs(seed, n):
    """Glossy events: a microfacet normal h up to ~35 degrees off +z, wi_b and its mirror image wo_b
    about h, and an offset wi_o a few degrees away; all valid (upper hemisphere, front of h)."""
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < n:
        h = unit([rng.normal() * 0.35, rng.normal() * 0.35, 1.0])
        wi = unit(rng.normal(size=3) * [1, 1, 0.5] + [0, 0, 0.6])
        wo = 2 * np.dot(wi, h) * h - wi
        wi_o = unit(wi + rng.normal(size=3) * 0.08)
        wo_o = 2 * np.dot(wi_o, h) * h - wi_o
        if min(wi[2], wo[2], wi_o[2], wo_o[2], np.dot(wi, h), np.dot(wi_o, h)) > 0.05:
            out.append((wi, wo, wi_o))
    return out


def test_perfect_mirror_by_hand():
    """at a perfect mirror (wo_b the mirror image of wi_b) the offset leaves as the mirror image of wi_o"""
    wo, j, ok = copy(sph(40, 10), sph(40, 190), sph(25, 70))
    assert ok, "a valid mirror configuration must succeed (ok = True)"
    want = np.array(sph(25, 250))
    assert np.allclose(wo, want, atol=1e-12), f"wo_o = {np.round(wo, 6)}, expected {np.round(want, 6)}"


def test_offset_keeps_the_half_vector():
    """the offset's half vector normalize(wi_o + wo_o) equals the base's (Eq. 15), on glossy events"""
    for wi, wo_b, wi_o in configs(3, 40):
        wo, _, ok = copy(wi, wo_b, wi_o)
        assert ok, f"a valid glossy event failed (wi_b {np.round(wi, 3)}, wo_b {np.round(wo_b, 3)}, wi_o {np.round(wi_o, 3)})"
        assert abs(np.linalg.norm(wo) - 1) < 1e-12, f"wo_o is not a unit vector: |wo_o| = {np.linalg.norm(wo)}"
        h_b, h_o = unit(np.add(wi, wo_b)), unit(wi_o + wo)
        assert np.allclose(h_o, h_b, atol=1e-10), (
            f"offset half vector {np.round(h_o, 4)} != base half vector {np.round(h_b, 4)}: copy h, not "
            "the outgoing direction, and reflect wi_o about h (not about the normal)")


def test_jacobian_by_hand():
    """wi_o = h reflects onto itself: J = |h . h| / |wo_b . h| = 1 / cos 30 = 1.1547"""
    wi_b, wo_b = sph(0), sph(60)                  # h is at 30 degrees
    h = sph(30)
    wo, j, ok = copy(wi_b, wo_b, h)
    assert ok and np.allclose(wo, h, atol=1e-12), f"wo_o = {np.round(wo, 6)}, expected h = {np.round(h, 6)}"
    want = 1.0 / math.cos(math.radians(30))
    assert j == pytest.approx(want, rel=1e-12), (
        f"J = {j:.6f}, expected {want:.6f}: |dh/dwo| = 1/(4 |wo . h|) on the base and on the offset, "
        "and J is the base's over the offset's")


def fd_jacobian(wi, wo_b, wi_o):
    e1, e2 = frame(wo_b)
    wo0, _, _ = copy(wi, wo_b, wi_o)
    f1, f2 = frame(wo0)

    def m(u, v):
        w, _, _ = copy(wi, unit(wo_b + u * e1 + v * e2), wi_o)
        return np.array([np.dot(w, f1), np.dot(w, f2)])

    return fd_determinant(m, H)


def test_jacobian_matches_finite_differences():
    """the Jacobian equals the finite-difference Jacobian of your shift map, on 40 glossy events"""
    far_from_one = 0
    for wi, wo_b, wi_o in configs(7, 40):
        _, j, ok = copy(wi, wo_b, wi_o)
        fd = fd_jacobian(wi, wo_b, wi_o)
        far_from_one += abs(fd - 1) > 1e-3
        assert j == pytest.approx(fd, rel=REL), (
            f"J = {j:.6g}, finite differences {fd:.6g} (wi_b {np.round(wi, 3)}, wo_b {np.round(wo_b, 3)}, "
            f"wi_o {np.round(wi_o, 3)})")
    assert far_from_one >= 30        # the comparison has power: J = 1 would fail most events


def test_shifting_back_inverts():
    """shifting the offset back to the base recovers wo_b, with the inverse Jacobian"""
    for wi, wo_b, wi_o in configs(9, 20):
        wo, j, _ = copy(wi, wo_b, wi_o)
        back, j_back, ok = copy(wi_o, wo, wi)
        assert ok and np.allclose(back, wo_b, atol=1e-10), "shifting back does not return to wo_b"
        assert j * j_back == pytest.approx(1.0, rel=1e-10), f"J * J_back = {j * j_back}, expected 1"


def test_fails_below_the_surface():
    """a copied direction below the surface (z <= 0) fails: ok = False, wo_o = (0, 0, 0), J = 0"""
    # h at 60 degrees; wi_o nearly along the normal reflects to (0.95, 0, -0.32): below the surface
    wo, j, ok = copy(sph(50), sph(70), sph(11.5))
    assert not ok, "the offset direction goes below the surface: the shift must fail (ok = False)"
    assert np.all(wo == 0) and j == 0.0, f"a failed shift returns (0, 0, 0) and J = 0, got {wo}, {j}"


def test_fails_on_the_back_of_the_microfacet():
    """wi_o on the back of the microfacet (wi_o . h <= 0) fails: ok = False, wo_o = (0, 0, 0), J = 0"""
    # h at 60 degrees in +x; wi_o at 60 degrees in -x: wi_o . h = cos 120 < 0
    wo, j, ok = copy(sph(50), sph(70), sph(60, 180))
    assert not ok, "wi_o . h < 0: the offset cannot reflect off this microfacet (ok = False)"
    assert np.all(wo == 0) and j == 0.0, f"a failed shift returns (0, 0, 0) and J = 0, got {wo}, {j}"
