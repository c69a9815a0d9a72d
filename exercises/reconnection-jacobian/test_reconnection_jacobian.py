"""Tests of the exercise "reconnection-jacobian". Each docstring is the line `gdlearn check` prints.

The reference values are computed here independently of gdlearn: by hand for simple geometry, and
by finite differences of the shift map itself -- perturb the base direction w on the unit sphere,
trace it to the surface through y (a plane or a sphere, intersected in numpy below), reconnect the
hit point to x'_b and measure how far the offset direction w' moved. All randomness is seeded.
"""
import math

import numpy as np
import pytest

from gdlearn.teaching.exercises import load_target
from gdlearn.testing.fdjac import H, fd_determinant, unit
from gdlearn.testing.fdjac import tangent_frame as frame
from gdlearn.shifts.path import jacobian_solid_angle_to_area

ex = load_target("reconnection-jacobian")

#: Finite-difference step (radians) and its accuracy: fourth-order central differences have error
#: ~h^4 |f^(5)| + eps/h ~ 1e-10 on these O(1) configurations. Near-grazing hits on a sphere are the
#: hard case: the hit point varies like a square root near tangency and |f^(5)| grows like cos^-9
#: (h = 1e-5 misses by 3e-5 at cos ~ 0.02; h = 1e-6 agrees to ~1e-9). So 1e-6 relative agreement is
#: demanded -- while any wrong cosine or distance factor is off by O(1).
REL = 1e-6




def hit(surface, o, d):
    """First hit of the ray o + t d (t > 0) with ("plane", point, normal) or ("sphere", centre, r)."""
    kind, p, q = surface
    if kind == "plane":
        den = np.dot(d, q)
        t = np.dot(p - o, q) / den if den != 0 else -1.0
        return o + t * d if t > 0 else None
    oc = o - p
    b = np.dot(oc, d)
    disc = b * b - (np.dot(oc, oc) - q * q)
    if disc < 0:
        return None
    t = -b - math.sqrt(disc)
    return o + t * d if t > 0 else None


def normal_at(surface, y):
    kind, p, q = surface
    return q if kind == "plane" else unit(y - p)


def fd_jacobian(x_b, x_o, surface, w0):
    """|det| of d(w')/d(w) by fourth-order central differences in orthonormal tangent charts."""
    e1, e2 = frame(w0)
    y0 = hit(surface, x_b, w0)
    wo0 = unit(y0 - x_o)
    f1, f2 = frame(wo0)

    def m(u, v):
        y = hit(surface, x_b, unit(w0 + u * e1 + v * e2))
        w = unit(y - x_o)
        return np.array([np.dot(w, f1), np.dot(w, f2)])

    return fd_determinant(m, H)


def configs(seed, n, grazing):
    """(surface, x_b, x_o, w0): a base vertex, an offset vertex nearby and a base direction to y."""
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < n:
        if rng.random() < 0.5:
            surface = ("plane", rng.normal(size=3) * 0.2, unit(rng.normal(size=3) * [0.3, 0.3, 1] + [0, 0, 1]))
        else:
            surface = ("sphere", rng.normal(size=3) * 0.2, rng.uniform(0.5, 1.5))
        x_b = rng.normal(size=3) * 0.5 + [0, 0, 3]
        y = hit(surface, x_b, unit([rng.normal() * 0.3, rng.normal() * 0.3, -1]))
        if y is None:
            continue
        if grazing:                      # slide x_b until the segment x_b -> y grazes y (cos ~ 0.01-0.05)
            n_y = normal_at(surface, y)
            e1, _ = frame(n_y)
            x_b = y + 3 * (e1 + rng.uniform(0.01, 0.05) * n_y)
            y2 = hit(surface, x_b, unit(y - x_b))
            if y2 is None or np.linalg.norm(y2 - y) > 1e-9:
                continue
        x_o = x_b + rng.normal(size=3) * 0.1
        out.append((surface, x_b, x_o, unit(y - x_b)))
    return out


def J(x_b, x_o, y, n):
    val = ex.reconnection_jacobian(tuple(map(float, x_b)), tuple(map(float, x_o)), tuple(map(float, y)),
                                   tuple(map(float, n)))
    assert isinstance(val, (float, np.floating)), f"return a float, got {type(val).__name__}"
    return float(val)


def test_same_vertex_gives_one():
    """an offset vertex equal to the base vertex changes nothing: J = 1"""
    got = J((0.3, -0.2, 2.0), (0.3, -0.2, 2.0), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0))
    assert got == pytest.approx(1.0, rel=1e-12), f"J = {got}, expected 1"


def test_distance_ratio_by_hand():
    """straight above y at distance 1 (base) and 2 (offset): J = (1/2)^2 = 0.25"""
    got = J((0, 0, 1.0), (0, 0, 2.0), (0, 0, 0.0), (0, 0, 1.0))
    assert got == pytest.approx(0.25, rel=1e-12), (
        f"J = {got}, expected 0.25: a solid angle shrinks with the squared distance, so moving the vertex "
        "away from y makes the same dA_y a smaller dw'")


def test_cosine_ratio_by_hand():
    """base straight above y, offset at 45 degrees: J = cos 45 / 2 = 0.3536 (distances 1 and sqrt 2)"""
    got = J((0, 0, 1.0), (1.0, 0, 1.0), (0, 0, 0.0), (0, 0, 1.0))
    want = math.sqrt(0.5) / 2.0
    assert got == pytest.approx(want, rel=1e-12), (
        f"J = {got}, expected {want:.6f}: dA_y = d^2 / |cos theta_y| dw on both segments -- the offset's "
        "cosine at y goes in the numerator, the base's in the denominator")


@pytest.mark.parametrize("grazing", [False, True], ids=["ordinary", "near-grazing"])
def test_matches_finite_differences(grazing):
    """equals the finite-difference Jacobian of the shift map, on 40 random configurations"""
    worst = 0.0
    for surface, x_b, x_o, w0 in configs(11 + grazing, 40, grazing):
        y = hit(surface, x_b, w0)
        fd = fd_jacobian(x_b, x_o, surface, w0)
        got = J(x_b, x_o, y, normal_at(surface, y))
        worst = max(worst, abs(got / fd - 1))
        assert got == pytest.approx(fd, rel=REL), (
            f"J = {got:.6g}, finite differences {fd:.6g} (x_b {np.round(x_b, 3)}, x'_b {np.round(x_o, 3)}, "
            f"y {np.round(y, 3)})")


def test_medium_vertex_has_unit_cosines():
    """a medium vertex (normal (0, 0, 0)): cosines are 1, only the distances remain"""
    got = J((0, 0, 1.0), (1.0, 0, 1.0), (0, 0, 0.0), (0, 0, 0.0))
    assert got == pytest.approx(0.5, rel=1e-12), f"J = {got}, expected (1 / sqrt 2)^2 = 0.5"


def test_shifting_back_inverts():
    """shifting back (x'_b -> x_b) gives the inverse Jacobian: J_forward * J_back = 1"""
    for surface, x_b, x_o, w0 in configs(5, 20, False):
        y = hit(surface, x_b, w0)
        n = normal_at(surface, y)
        prod = J(x_b, x_o, y, n) * J(x_o, x_b, y, n)
        assert prod == pytest.approx(1.0, rel=1e-12), f"J_forward * J_back = {prod}, expected 1"


def test_area_measure_jacobian_is_one():
    """converted to the area measure (GPM Eq. 4), your Jacobian is exactly 1: y does not move"""
    for surface, x_b, x_o, w0 in configs(8, 20, False):
        y = tuple(hit(surface, x_b, w0))
        n = tuple(normal_at(surface, np.array(y)))
        j_area = jacobian_solid_angle_to_area(J(x_b, x_o, y, n), tuple(x_b), y, n, tuple(x_o), y, n)
        assert j_area == pytest.approx(1.0, rel=1e-10), f"area-measure Jacobian {j_area}, expected 1"


def test_degenerate_input_gives_zero():
    """degenerate input (x'_b or x_b on y, base segment grazing y) returns 0, never NaN or an error"""
    y, n = (0.0, 0.0, 0.0), (0.0, 0.0, 1.0)
    cases = {"x'_b on y": ((0, 0, 1.0), y), "x_b on y": (y, (0, 0, 1.0)),
             "base segment grazing y": ((1.0, 0, 0.0), (0, 0, 1.0))}
    for what, (x_b, x_o) in cases.items():
        got = J(x_b, x_o, y, n)
        assert got == 0.0, f"{what}: J = {got}, expected 0.0 (a failed shift)"
