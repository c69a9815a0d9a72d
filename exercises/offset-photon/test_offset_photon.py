"""Tests of the exercise "offset-photon". Each docstring is the line `gdlearn check` prints.

Hand values first; then the properties of Eq. 5 (it keeps the photon's local coordinates, so it is
rigid and undoes itself) and gdlearn's compiled version; then Eq. 6 against the finite-difference
Jacobian of the projection itself (gdlearn.testing.fdjac: a patch around y* in the plane of n*,
projected from the parent onto a sphere and onto a tilted plane), and its degenerate cases. All
randomness is seeded.
"""
import math

import numpy as np

from gdlearn.kernels.vec import coordinate_system
from gdlearn.shifts.photon import offset_target as gdlearn_offset_target
from gdlearn.shifts.photon import projection_jacobian as gdlearn_projection_jacobian
from gdlearn.teaching.exercises import load_target
from gdlearn.testing.fdjac import fd_jacobian_at_point, tangent_frame, unit

ex = load_target("offset-photon")

#: fourth-order central differences (gdlearn.testing.fdjac): ~1e-10 on this geometry; a wrong
#: cosine or distance factor is off by O(1)
REL = 1e-6


def frame(n):
    """(n, s, t) as 3-tuples: gdlearn's branchless frame of the unit normal n."""
    n = tuple(float(c) for c in unit(n))
    s, t = coordinate_system(n)
    return n, s, t


def random_frame(rng):
    """A frame whose normal is in no special direction, with a random twist about it."""
    n = unit(rng.normal(size=3))
    e1, e2 = tangent_frame(n)
    a = rng.uniform(0, 2 * math.pi)
    s = math.cos(a) * e1 + math.sin(a) * e2
    return tuple(map(float, n)), tuple(map(float, s)), tuple(map(float, np.cross(n, s)))


def target(y, z, fr, z_o, fr_o):
    out = ex.offset_target(tuple(map(float, y)), tuple(map(float, z)), fr, tuple(map(float, z_o)), fr_o)
    assert len(out) == 3, "offset_target returns a point (3 numbers)"
    return np.array(out, dtype=float)


def local(v, fr):
    n, s, t = (np.array(a) for a in fr)
    return np.array([np.dot(v, s), np.dot(v, t), np.dot(v, n)])


def test_equal_frames_by_hand():
    """offset_target: with the same frame at z and z', Eq. 5 is the translation y* = y + (z' - z) (by hand)"""
    fr = frame((0.0, 1.0, 0.0))
    got = target((0.3, -1.0, 0.2), (0.25, -1.0, 0.05), fr, (0.5, -1.0, -0.2), fr)
    want = np.array([0.55, -1.0, -0.05])
    assert np.allclose(got, want, atol=1e-12), f"y* = {np.round(got, 6)}, expected y + (z' - z) = {want}"


def test_local_coordinates_are_kept():
    """offset_target: y* - z' has in the offset's frame the coordinates that y - z has in the base frame"""
    rng = np.random.default_rng(5)
    for _ in range(20):
        fr, fr_o = random_frame(rng), random_frame(rng)
        y, z, z_o = rng.normal(size=3), rng.normal(size=3), rng.normal(size=3)
        got = target(y, z, fr, z_o, fr_o)
        want, mine = local(y - z, fr), local(got - z_o, fr_o)
        hint = (" -- y* - z' equals y - z: the offset was copied in world space, not through the frames (M' M^-1)"
                if np.allclose(got - z_o, y - z, atol=1e-9) else "")
        assert np.allclose(mine, want, atol=1e-10), \
            f"local coordinates of y - z: {np.round(want, 6)}; of y* - z': {np.round(mine, 6)}{hint}"


def test_tangent_plane_goes_to_tangent_plane():
    """offset_target: a photon in the base tangent plane lands in the offset's tangent plane, as far from z' as it was from z"""
    z, z_o = np.array([0.1, 0.2, -0.3]), np.array([0.15, 0.1, -0.25])
    fr = frame((0.0, 0.0, 1.0))
    fr_o = frame((0.3, 0.4, 0.866))                  # a curved surface: the normal turned by ~30 degrees
    y = z + 0.07 * np.array(fr[1]) - 0.04 * np.array(fr[2])
    got = target(y, z, fr, z_o, fr_o)
    off_plane = float(np.dot(got - z_o, fr_o[0]))
    hint = (" -- y* - z' equals y - z: the offset was copied in world space, not through the frames (M' M^-1)"
            if np.allclose(got - z_o, y - z, atol=1e-12) else "")
    assert abs(off_plane) < 1e-12, f"y* lies {off_plane:.3g} off the offset's tangent plane{hint}"
    assert math.isclose(np.linalg.norm(got - z_o), np.linalg.norm(y - z), rel_tol=1e-12), \
        f"|y* - z'| = {np.linalg.norm(got - z_o):.6f}, |y - z| = {np.linalg.norm(y - z):.6f}: Eq. 5 is rigid"


def test_shifting_back_returns_the_photon():
    """offset_target: y* shifted back from z' to z (the same formula, frames swapped) is y again"""
    rng = np.random.default_rng(8)
    for _ in range(20):
        fr, fr_o = random_frame(rng), random_frame(rng)
        y, z, z_o = rng.normal(size=3), rng.normal(size=3), rng.normal(size=3)
        back = target(target(y, z, fr, z_o, fr_o), z_o, fr_o, z, fr)
        assert np.allclose(back, y, atol=1e-10), f"y = {np.round(y, 6)}, shifted there and back: {np.round(back, 6)}"


def test_offset_target_agrees_with_gdlearn():
    """offset_target: the same points as gdlearn's compiled version (gdlearn.shifts.photon.offset_target)"""
    rng = np.random.default_rng(11)
    for _ in range(20):
        fr, fr_o = random_frame(rng), random_frame(rng)
        y, z, z_o = (tuple(map(float, rng.normal(size=3))) for _ in range(3))
        mine, theirs = target(y, z, fr, z_o, fr_o), np.array(gdlearn_offset_target(y, z, fr, z_o, fr_o))
        assert np.allclose(mine, theirs, atol=1e-12), f"yours {np.round(mine, 6)}, gdlearn's {np.round(theirs, 6)}"


def jac(y_parent, y_star, n_star, y_hit, n_hit):
    args = [tuple(map(float, v)) for v in (y_parent, y_star, n_star, y_hit, n_hit)]
    return float(ex.projection_jacobian(*args))


def test_projection_jacobian_by_hand():
    """projection_jacobian: by hand -- y' twice as far from the parent as y*, both facing it: 4; y' = y*: 1"""
    p, up = (0.0, 0.0, 2.0), (0.0, 0.0, 1.0)
    got = jac(p, (0.0, 0.0, 1.0), up, (0.0, 0.0, 0.0), up)
    assert math.isclose(got, 4.0, rel_tol=1e-12), \
        f"d* = 1, d' = 2, both cosines 1: (1 / 1) / (1 / 4) = 4, got {got}" + \
        (" -- that is 1/4: the ratio is upside down" if math.isclose(got, 0.25) else "")
    n = tuple(unit((0.2, 0.1, 1.0)))
    got = jac(p, (0.3, -0.1, 0.4), n, (0.3, -0.1, 0.4), n)
    assert math.isclose(got, 1.0, rel_tol=1e-12), f"no projection (y' = y*, same normal) must give 1, got {got}"


def hit_sphere(o, d, c, rad):
    d = unit(d)
    b = np.dot(o - c, d)
    disc = b * b - (np.dot(o - c, o - c) - rad * rad)
    return None if disc < 0 else o + (-b - math.sqrt(disc)) * d


def check_projection(project, seed, n_cases):
    """Finite-difference |dy'/dy*| of ``project(y_parent, point) -> (hit, normal)`` around random y*."""
    rng = np.random.default_rng(seed)
    done = 0
    while done < n_cases:
        yp = np.array([0.0, 0.0, 3.0]) + rng.normal(0, 0.4, 3)
        ystar = np.array([0.0, 0.0, 1.1]) + rng.normal(0, 0.25, 3)
        nstar = unit(np.array([0.0, 0.0, 1.0]) + rng.normal(0, 0.4, 3))
        e1, e2 = tangent_frame(nstar)
        f = lambda u, v: project(yp, ystar + u * e1 + v * e2)    # noqa: E731
        h0 = f(0.0, 0.0)
        fd = fd_jacobian_at_point(f)
        if h0 is None or fd is None or abs(np.dot(h0[1], unit(h0[0] - yp))) < 0.1:
            continue                          # missed, or too grazing for a clean finite difference
        mine = jac(yp, ystar, nstar, h0[0], h0[1])
        a, b = ystar - yp, h0[0] - yp
        same_n = (abs(np.dot(h0[1], a)) / np.dot(a, a) ** 1.5) / (abs(np.dot(h0[1], b)) / np.dot(b, b) ** 1.5)
        hint = (" -- that is 1 / (finite differences): the ratio is upside down" if math.isclose(mine * fd, 1.0, rel_tol=1e-4)
                else " -- that is the ratio with the hit's normal n' at y* too: cos* belongs to n*, the normal at y*"
                if math.isclose(mine, same_n, rel_tol=1e-9) else "")
        assert math.isclose(mine, fd, rel_tol=REL), \
            f"y_parent {np.round(yp, 3)}, y* {np.round(ystar, 3)}: yours {mine:.8f}, finite differences {fd:.8f}{hint}"
        done += 1


def test_projection_onto_a_sphere():
    """projection_jacobian: a small patch around y* projected from the parent onto a sphere -- its area ratio by finite differences"""
    c, rad = np.array([0.0, 0.0, 0.0]), 1.0

    def project(yp, q):
        hit = hit_sphere(yp, q - yp, c, rad)
        return None if hit is None else (hit, (hit - c) / rad)
    check_projection(project, 21, 12)


def test_projection_onto_a_tilted_plane():
    """projection_jacobian: the same onto a tilted plane (y' beyond or before y*, in no special direction)"""
    p0, m = np.array([0.1, -0.2, 0.9]), unit([0.4, -0.3, 1.0])

    def project(yp, q):
        d = unit(q - yp)
        den = np.dot(d, m)
        t = np.dot(p0 - yp, m) / den if den != 0 else -1.0
        return None if t <= 0 else (yp + t * d, m)
    check_projection(project, 22, 12)


def test_projection_jacobian_agrees_with_gdlearn():
    """projection_jacobian: the same values as gdlearn's compiled version (gdlearn.shifts.photon.projection_jacobian)"""
    rng = np.random.default_rng(13)
    for _ in range(20):
        args = [tuple(map(float, rng.normal(size=3))) for _ in range(5)]
        args[2], args[4] = tuple(map(float, unit(args[2]))), tuple(map(float, unit(args[4])))
        mine, theirs = jac(*args), float(gdlearn_projection_jacobian(*args))
        assert math.isclose(mine, theirs, rel_tol=1e-12), f"yours {mine}, gdlearn's {theirs}"


def test_projection_jacobian_degenerate():
    """projection_jacobian: 0.0 -- never NaN, infinity or an exception -- for y* or y' at the parent and for a grazing hit"""
    p, up = (0.0, 0.0, 2.0), (0.0, 0.0, 1.0)
    cases = {"y* at the parent": (p, p, up, (0.0, 0.0, 0.0), up),
             "y' at the parent": (p, (0.0, 0.0, 1.0), up, p, up),
             "a grazing hit (cos' = 0)": (p, (0.0, 0.0, 1.0), up, (0.0, 0.0, 0.0), (1.0, 0.0, 0.0))}
    for what, args in cases.items():
        try:
            got = jac(*args)
        except Exception as err:              # noqa: BLE001  (the message names the case)
            raise AssertionError(f"{what}: raised {type(err).__name__}: {err}; return 0.0 instead") from None
        assert got == 0.0, f"{what}: expected 0.0 (the shift then fails), got {got}"
