"""The specular tracer and the relaxed walk (gdlearn.shifts.specular_trace; Gruson et al. 2018 Sec. 6.1)
on the chains of tests/test_shifts_manifold.py (mirror, grazing mirror, refraction, glass ball,
ball + mirror), against that file's numpy tracer (the laws of reflection and refraction written
independently of the code under test):

* the chain traced from x_b through x_1 is the numpy tracer's, and its last ray points at x_c;
* the relaxed acceptance holds exactly when the traced end lies within r of the target and of the
  gather point;
* a relaxed walk with r = 0 is the exact walk bit for bit; with a large r it stops at its start, on
  the chain the tracer takes through that start.
"""
import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(__file__))
from test_shifts_geometry import Plane, Sphere  # noqa: E402
from test_shifts_manifold import SCENES, T, Scene, _configs, moved_chains  # noqa: E402

from gdlearn.shifts import manifold as M  # noqa: E402
from gdlearn.shifts.specular_trace import relaxed_accept, traced_chain  # noqa: E402


def _targets(sc, x_b, X, x_c):
    targets = np.zeros((sc.k, 2))
    assert M.half_vector_targets(T(x_b), X, T(x_c), sc.rows, sc.etas, sc.refract, sc.k, targets)
    return targets


@pytest.mark.parametrize("name", list(SCENES))
def test_traced_chain_is_the_light_path(name):
    """Every vertex within 1e-9 of the numpy tracer's (both trace the same rays in double precision;
    a swapped relative index, a reflection's sign or the wrong root of a sphere is off by 1e-2 or
    more), the last direction towards x_c to 1e-9."""
    rng = np.random.default_rng(5 + sum(map(ord, name)))
    sc, cfgs = _configs(name, rng, 20)
    for x_b, x1, _ in cfgs:
        X, x_c = sc.trace_chain(x_b, x1)
        X = np.array(X, float)
        Xt = np.full_like(X, np.nan)
        ok, w = traced_chain(T(x_b), X, sc.rows, sc.etas, sc.refract, _targets(sc, x_b, X, x_c), sc.k, Xt)
        assert ok, name
        assert np.allclose(Xt, X, rtol=0, atol=1e-9), (name, Xt - X)
        to_end = (x_c - X[-1]) / np.linalg.norm(x_c - X[-1])
        assert np.allclose(w, to_end, rtol=0, atol=1e-9), name


def test_traced_chain_enters_a_ball_from_outside():
    """A mirror, then a glass ball (its near side first: the ray from the mirror enters it from
    outside), then a wall: the chains of test_shifts_manifold.py all start their ball at x_1."""
    ball = Sphere([2.0, 0.0, 1.0], 0.5)
    sc = Scene([Plane([0, 0, 0], [0, 0, 1]), ball, ball],
               [M.plane_row([0, 0, 0], [0, 0, 1], [1, 0, 0]), M.sphere_row([2.0, 0.0, 1.0], 0.5),
                M.sphere_row([2.0, 0.0, 1.0], 0.5)], [False, True, True], Plane([4.0, 0, 0], [-1, 0, 0]))
    rng = np.random.default_rng(31)
    traced = 0
    for _ in range(40):
        x_b = np.array([-1.0, 0.0, 1.0]) + rng.normal(size=3) * 0.05
        x1 = np.array([0.5 + rng.normal() * 0.03, rng.normal() * 0.03, 0.0])
        res = sc.trace_chain(x_b, x1)
        if res is None:
            continue
        X = np.array(res[0], float)
        Xt = np.full_like(X, np.nan)
        ok, _ = traced_chain(T(x_b), X, sc.rows, sc.etas, sc.refract, _targets(sc, x_b, X, res[1]), sc.k, Xt)
        assert ok and np.allclose(Xt, X, rtol=0, atol=1e-9), Xt - X
        traced += 1
    assert traced >= 20


def _perp(w):
    p = np.cross(w, [0.0, 0.0, 1.0] if abs(w[2]) < 0.9 else [1.0, 0.0, 0.0])
    return p / np.linalg.norm(p)


@pytest.mark.parametrize("name", ["sphere2", "sphere+mirror3"])
def test_relaxed_acceptance_is_the_kernel(name):
    """The base chain's traced end is x_c. A target moved across the last ray by 0.9 r is accepted, by
    1.1 r refused; a gather point 1.1 r away refuses it too (the reference code's max of the two
    distances)."""
    rng = np.random.default_rng(23)
    sc, cfgs = _configs(name, rng, 10)
    r = 1e-3
    for x_b, x1, _ in cfgs:
        X, x_c = sc.trace_chain(x_b, x1)
        X = np.array(X, float)
        targets = _targets(sc, x_b, X, x_c)
        side = _perp((x_c - X[-1]) / np.linalg.norm(x_c - X[-1]))
        Xt = np.empty_like(X)
        near, far = x_c + 0.9 * r * side, x_c + 1.1 * r * side
        args = (sc.rows, sc.etas, sc.refract, targets, sc.k, Xt)
        assert relaxed_accept(T(x_b), X, T(near), T(near), r, *args)
        assert not relaxed_accept(T(x_b), X, T(far), T(far), r, *args)
        assert not relaxed_accept(T(x_b), X, T(near), T(x_c + 1.1 * r * side), r, *args)
        assert relaxed_accept(T(x_b), X, T(near), T(x_c - 0.9 * r * side), r, *args)


@pytest.mark.parametrize("name", list(SCENES))
def test_relaxed_walk(name):
    """From the predicted start to an endpoint moved by a pixel-sized step: with r = 0 the relaxed
    walk is the exact walk (same iterations, same chain, bit for bit); with r = 1 (the whole scene)
    it stops before any Newton step, on the chain the tracer takes through the predicted start."""
    sc, chains = moved_chains(name, 29 + sum(map(ord, name)), 10)
    walked = 0
    for x_b, X, x_c, _, x_ct, targets, S in chains:
        n_c = T(sc.end.normal(x_c))
        runs = {}
        for label, relax in (("exact", None), ("r=0", (T(x_ct), 0.0)), ("r=1", (T(x_ct), 1.0))):
            Xo = np.empty_like(X)
            runs[label] = M.predicted_walk(T(x_b), X, T(x_c), n_c, T(x_ct), S, sc.rows, sc.etas, sc.refract, targets,
                                           sc.k, Xo, relax), Xo
        (ok_e, it_e, _), Xe = runs["exact"]
        (ok_0, it_0, _), X0 = runs["r=0"]
        assert (ok_0, it_0) == (ok_e, it_e) and np.array_equal(X0, Xe), name
        (ok_1, it_1, _), X1 = runs["r=1"]
        assert ok_1 and it_1 == 0, name
        start = np.empty_like(X)
        M.predicted_start(X, T(x_c), n_c, T(x_ct), S, sc.rows, sc.k, start)
        along = sc.trace_chain(x_b, start[0])
        assert along is not None and np.allclose(X1, along[0], rtol=0, atol=1e-9), name
        walked += 1
    assert walked >= 6, name
