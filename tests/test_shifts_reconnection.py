"""Reconnection shift (STAR Sec. 3.3): its solid-angle Jacobian against the finite-difference
Jacobian of the shift map, its area-measure Jacobian (1), reversibility and failure cases."""
import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(__file__))
from test_shifts_geometry import Plane, Sphere, direction_chart, fd_jacobian, trace, unit  # noqa: E402

from gdlearn.kernels import layout as L  # noqa: E402
from gdlearn.shifts.path import jacobian_solid_angle_to_area  # noqa: E402
from gdlearn.shifts.reconnection import (MIN_DISTANCE_RATIO, can_reconnect, far_enough, reconnect,  # noqa: E402
                                         reconnection_jacobian_solid_angle)

T = tuple


def _random_configs(rng, n, grazing=False):
    """(surface, x_b, x_b_offset, w0) with the ray x_b + t w0 hitting the surface."""
    out = []
    while len(out) < n:
        if rng.random() < 0.5:
            surf = Plane([0, 0, 0], unit(rng.normal(size=3) * [0.3, 0.3, 1] + [0, 0, 1]))
        else:
            surf = Sphere(rng.normal(size=3) * 0.2, rng.uniform(0.5, 1.5))
        x_b = rng.normal(size=3) * 0.5 + [0, 0, 3]
        # aim at a random surface point (from above): for grazing, tilt toward the tangent plane
        target = trace(surf, x_b + [0, 0, 0], unit([rng.normal() * 0.3, rng.normal() * 0.3, -1]))
        if target is None:
            continue
        n_y = surf.normal(target)
        w0 = unit(target - x_b)
        cos_y = abs(np.dot(n_y, w0))
        if grazing and not cos_y < 0.05:
            # move x_b along the tangent plane of y until the segment grazes y (cos ~ 0.01-0.05)
            e1 = unit(np.cross(n_y, rng.normal(size=3)))
            x_b = target + 3 * (e1 + rng.uniform(0.01, 0.05) * n_y * np.sign(np.dot(x_b - target, n_y)))
            w0 = unit(target - x_b)
            if trace(surf, x_b, w0) is None or np.linalg.norm(trace(surf, x_b, w0) - target) > 1e-6:
                continue
        x_o = x_b + rng.normal(size=3) * 0.1
        out.append((surf, x_b, x_o, w0))
    return out


@pytest.mark.parametrize("grazing", [False, True])
def test_solid_angle_jacobian_matches_finite_differences(grazing):
    rng = np.random.default_rng(7 + grazing)
    checked = 0
    for surf, x_b, x_o, w0 in _random_configs(rng, 60, grazing):
        def shift(u, v):
            w = direction_chart(w0, u, v)
            y = trace(surf, x_b, w)
            if y is None:
                return None
            w_off = unit(y - x_o)
            return w_off, w_off
        fd = fd_jacobian(shift)
        if fd is None:
            continue
        y = trace(surf, x_b, w0)
        j = reconnection_jacobian_solid_angle(T(x_b), T(x_o), T(y), T(surf.normal(y)))
        # 1e-6 relative: the FD error is <~1e-9 even at cos ~ 0.01 (test_shifts_geometry docstring)
        assert j == pytest.approx(fd, rel=1e-6), (x_b, x_o, y)
        # the area form is 1: converting the solid-angle Jacobian back must give exactly that
        ja = jacobian_solid_angle_to_area(j, T(x_b), T(y), T(surf.normal(y)), T(x_o), T(y), T(surf.normal(y)))
        assert ja == pytest.approx(1.0, rel=1e-12)
        w, dist, j_area, j_sa, ok = reconnect(T(x_b), T(x_o), T(y), T(surf.normal(y)))
        assert ok and j_area == 1.0 and j_sa == pytest.approx(j, rel=1e-14)
        assert np.allclose(np.asarray(x_o) + dist * np.asarray(w), y, atol=1e-12)
        checked += 1
    assert checked >= 40          # most random configurations must actually be tested


def test_wrong_formula_is_rejected():
    """The FD comparison must be able to fail: dropping the cosine ratio misses by far more than 1e-6."""
    rng = np.random.default_rng(3)
    surf, x_b, x_o, w0 = _random_configs(rng, 1, grazing=True)[0]
    y = trace(surf, x_b, w0)
    fd = fd_jacobian(lambda u, v: (lambda yy: None if yy is None else (unit(yy - x_o),) * 2)(
        trace(surf, x_b, direction_chart(w0, u, v))))
    wrong = np.sum((y - x_b) ** 2) / np.sum((y - x_o) ** 2)
    assert abs(wrong / fd - 1) > 1e-3


def test_reversible_and_consistent_both_ways():
    """Shifting back (offset -> base) gives the inverse Jacobian: J(x_b -> x'_b) J(x'_b -> x_b) = 1."""
    rng = np.random.default_rng(11)
    for surf, x_b, x_o, w0 in _random_configs(rng, 30):
        y = trace(surf, x_b, w0)
        n_y = T(surf.normal(y))
        w1, d1, _, j1, ok1 = reconnect(T(x_b), T(x_o), T(y), n_y)
        w2, d2, _, j2, ok2 = reconnect(T(x_o), T(x_b), T(y), n_y)
        assert ok1 and ok2
        assert j1 * j2 == pytest.approx(1.0, rel=1e-12)
        assert np.allclose(np.asarray(x_b) + d2 * np.asarray(w2), y, atol=1e-12)   # back on the base


def test_connectability_table():
    D, G, S, M = L.V_DIFFUSE, L.V_GLOSSY, L.V_SPECULAR, L.V_MEDIUM
    for a in (D, G, M):
        for b in (D, G, M):
            for c in (D, G, M):
                assert can_reconnect(a, b, c)
    for trio in ((S, D, D), (D, S, D), (D, D, S), (G, G, S)):
        assert not can_reconnect(*trio)


def test_failures_are_flags_not_exceptions():
    y, n = (0.0, 0.0, 0.0), (0.0, 0.0, 1.0)
    # offset vertex coincides with y
    *_, ok = reconnect((0.0, 0.0, 1.0), y, y, n)
    assert not ok
    # offset segment exactly grazing y: cos theta'_y = 0
    w, d, ja, js, ok = reconnect((0.0, 0.0, 1.0), (1.0, 0.0, 0.0), y, n)
    assert not ok and ja == 0.0 and js == 0.0
    # medium vertex (zero normal): cosines are 1, the Jacobian is the squared distance ratio
    w, d, ja, js, ok = reconnect((0.0, 0.0, 1.0), (0.0, 0.0, 2.0), y, (0.0, 0.0, 0.0))
    assert ok and js == pytest.approx(1.0 / 4.0)
    # non-finite input: no exception, failure flag
    *_, ok = reconnect((0.0, 0.0, 1.0), (np.inf, 0.0, 0.0), y, n)
    assert not ok


def test_short_segment_guard_is_symmetric_and_bounds_the_distance_ratio():
    """far_enough reads x_b and x'_b alike (the backward shift decides the same), admits exactly the
    y whose two segments are >= c |x_b - x'_b| (checked against a direct numpy evaluation), and on
    those the Jacobian's distance ratio stays in [(c/(c+1))^2, ((c+1)/c)^2]; without the guard the
    same draws reach ratios far outside it."""
    rng = np.random.default_rng(11)
    c = MIN_DISTANCE_RATIO
    lo, hi = (c / (c + 1)) ** 2, ((c + 1) / c) ** 2
    ratios, admitted = [], 0
    for _ in range(4000):
        xb = rng.normal(size=3)
        xo = xb + rng.normal(size=3) * 0.05
        y = xb + rng.normal(size=3) * rng.choice([0.02, 0.1, 1.0])
        ok = far_enough(tuple(xb), tuple(xo), tuple(y))
        assert ok == far_enough(tuple(xo), tuple(xb), tuple(y))
        delta = np.linalg.norm(xb - xo)
        db, do = np.linalg.norm(y - xb), np.linalg.norm(y - xo)
        assert ok == (db >= c * delta and do >= c * delta)
        r = db ** 2 / do ** 2
        ratios.append(r)
        if ok:
            admitted += 1
            assert lo * (1 - 1e-12) <= r <= hi * (1 + 1e-12), (r, lo, hi)
    assert 500 < admitted < 3500          # both outcomes are exercised
    assert max(ratios) > 10 * hi and min(ratios) < lo / 10
