"""Manifold exploration shift (Jakob & Marschner 2012; GPM Eq. 7-8): specular chains of length 1-3
(mirror, refraction, a glass sphere, sphere + mirror), checked three independent ways:

* the offset chain is a real specular path: tracing forward from x'_b through x'_1 with the laws of
  reflection and refraction (written here in numpy, not the code under test) lands on x_c;
* the Jacobian |dx'_1/dx_1| equals the finite-difference Jacobian of the whole shift map (perturb the
  base vertex x_1 on its surface, re-trace the base chain to a new x_c, re-run the walk);
* walking back from the offset recovers the base chain (reversibility) and the inverse Jacobian.

Unreachable targets (a finite mirror too small, total internal reflection, too far for 5 iterations)
fail with a flag.
"""
import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(__file__))
from test_shifts_geometry import Plane, Sphere, fd_jacobian, unit  # noqa: E402

from gdlearn.shifts import manifold as M  # noqa: E402

T = tuple
GLASS = 1.5


def _bend(w, n, eta, refract):
    """Direction after scattering the travelling direction w at a surface with outward normal n."""
    if not refract:
        return w - 2 * np.dot(w, n) * n
    c = -np.dot(w, n)                         # cosine on the arrival side (> 0: from outside)
    eta_ti = 1 / eta if c > 0 else eta
    nn = n if c > 0 else -n
    c = abs(c)
    s2 = eta_ti ** 2 * (1 - c * c)
    if s2 >= 1:
        return None
    return unit(eta_ti * w + (eta_ti * c - np.sqrt(1 - s2)) * nn)


class Scene:
    """A chain of analytic surfaces (test geometry) mirrored by gdlearn shape rows."""

    def __init__(self, surfaces, rows, refract, end):
        self.surfaces, self.rows, self.end = surfaces, np.array(rows), end
        self.refract = np.array(refract, bool)
        self.etas = np.full(len(surfaces), GLASS)
        self.k = len(surfaces)

    def trace_chain(self, x_b, x1):
        """Base chain from x_b through x1 (on surface 0): list of vertices and the end point."""
        pts = [np.asarray(x1, float)]
        w = unit(pts[0] - x_b)
        for j, s in enumerate(self.surfaces):
            w = _bend(w, s.normal(pts[-1]), GLASS, self.refract[j])
            if w is None:
                return None
            nxt = self.surfaces[j + 1] if j + 1 < self.k else self.end
            t = nxt.intersect(pts[-1], w)
            if np.isnan(t):
                return None
            pts.append(pts[-1] + t * w)
        return np.array(pts[:-1]), pts[-1]

    def shift(self, x_b, chain, x_c, x_bo, max_iter=M.MAX_ITER, check=False):
        out = np.zeros((3, 3))
        j, ok, it = M.manifold_shift(T(x_b), T(x_bo), np.ascontiguousarray(chain), T(x_c),
                                     T(self.end.normal(x_c)), self.rows, self.etas, self.refract,
                                     self.k, out, max_iter, check)
        return j, ok, it, out[:self.k].copy()


def mirror_scene(extent=np.inf):
    return Scene([Plane([0, 0, 0], [0, 0, 1])],
                 [M.plane_row([0, 0, 0], [0, 0, 1], [1, 0, 0], (extent, extent))],
                 [False], Plane([0, 0, 1.5], [0.1, 0, -1]))


def mirror_grazing_scene():
    """Light skimming a mirror: incidence cosines ~0.03-0.08 (the near-grazing case)."""
    return Scene([Plane([0, 0, 0], [0, 0, 1])], [M.plane_row([0, 0, 0], [0, 0, 1], [1, 0, 0])],
                 [False], Plane([3, 0, 0], [-1, 0, 0.1]))


def refraction_scene():
    return Scene([Plane([0, 0, 0], [0, 0, 1])], [M.plane_row([0, 0, 0], [0, 0, 1], [1, 0, 0])],
                 [True], Plane([0, 0, -1], [0.2, 0, 1]))


def sphere_scene():
    s = Sphere([0, 0, 0], 1.0)
    # the floor sits before the ball lens's focus (back focal distance 0.5 R for eta = 1.5): past the
    # focus x_1 -> x_c nears a caustic, the inverse is ill-conditioned and Newton needs many steps
    return Scene([s, s], [M.sphere_row([0, 0, 0], 1.0)] * 2, [True, True], Plane([0, 0, -1.3], [0, 0, 1]))


def sphere_mirror_scene():
    s = Sphere([0, 0, 0], 1.0)
    n = unit([0.4, 0, 1])
    return Scene([s, s, Plane([0, 0, -1.25], n)],
                 [M.sphere_row([0, 0, 0], 1.0), M.sphere_row([0, 0, 0], 1.0),
                  M.plane_row([0, 0, -1.25], n, [1, 0, 0])],
                 [True, True, False], Plane([4, 0, 0], [-1, 0, 0]))


SCENES = {"mirror": mirror_scene, "mirror_grazing": mirror_grazing_scene,
          "refraction": refraction_scene, "sphere2": sphere_scene, "sphere+mirror3": sphere_mirror_scene}


def _configs(name, rng, n):
    """Random base paths (x_b, x_1) that trace to the end surface, and an offset x'_b nearby."""
    sc = SCENES[name]()
    out = []
    while len(out) < n:
        x_b = np.array([rng.normal() * 0.3, rng.normal() * 0.3, 3.0])
        if name == "mirror_grazing":
            x_b = np.array([-3.0 + rng.normal() * 0.3, rng.normal() * 0.3, 0.15 + rng.normal() * 0.02])
        if name.startswith("sphere"):
            x1 = unit([rng.normal() * 0.25, rng.normal() * 0.25, 1.0])
        else:
            x1 = np.array([rng.normal() * 0.4, rng.normal() * 0.4, 0.0])
        if sc.trace_chain(x_b, x1) is None:
            continue
        x_bo = x_b + rng.normal(size=3) * 0.02          # a pixel-sized move of the offset vertex
        out.append((x_b, x1, x_bo))
    return sc, out


def _forward_hits(sc, x_bo, chain_o, x_c):
    """Independent check: the offset chain obeys the specular laws and ends on x_c."""
    res = sc.trace_chain(x_bo, chain_o[0])
    return res is not None and np.allclose(res[0], chain_o, atol=1e-8) and np.allclose(res[1], x_c, atol=1e-8)


@pytest.mark.parametrize("name", list(SCENES))
def test_walk_connects_and_jacobian_matches_finite_differences(name):
    rng = np.random.default_rng(sum(map(ord, name)))        # a fixed seed per scene
    sc, cfgs = _configs(name, rng, 25)
    checked = 0
    for x_b, x1, x_bo in cfgs:
        chain, x_c = sc.trace_chain(x_b, x1)
        j, ok, it, chain_o = sc.shift(x_b, chain, x_c, x_bo)
        assert it <= M.MAX_ITER
        if not ok:
            # near the ball lens's caustic 5 Newton steps may not suffice: a failure, flagged
            assert j == 0.0 and name.startswith("sphere"), (name, x_b, x1, x_bo)
            continue
        assert _forward_hits(sc, x_bo, chain_o, x_c)
        s0 = sc.surfaces[0]

        def shift(u, v):
            y1 = s0.chart(x1, u, v)
            base = sc.trace_chain(x_b, y1)
            if base is None:
                return None
            jj, good, _, ch = sc.shift(x_b, base[0], base[1], x_bo)
            return (ch[0], s0.normal(ch[0])) if good else None
        # h = 1e-4: the walk's positions are exact to ~1e-14 (converged to |c| < 1e-12, quadratic),
        # so round-off in the FD is ~1e-10; fourth-order truncation ~h^4 = 1e-16. The Jacobian
        # inside manifold_shift comes from central differences of the constraints (~1e-9). 1e-6.
        fd = fd_jacobian(shift, h=1e-4)
        assert fd is not None
        assert j == pytest.approx(fd, rel=1e-6), (name, x_b, x1, x_bo)
        checked += 1
    assert checked >= 0.8 * len(cfgs)


@pytest.mark.parametrize("name", list(SCENES))
def test_reversible(name):
    """Where the shift claims reversibility (check_reversible=True and ok), walking back recovers the
    base chain and the inverse Jacobian. Near the ball lens's caustic (marginal rays focus early)
    two chains can join the same endpoints: then the check must report the shift as failed."""
    rng = np.random.default_rng(3)
    sc, cfgs = _configs(name, rng, 10)
    n_ok = 0
    for x_b, x1, x_bo in cfgs:
        chain, x_c = sc.trace_chain(x_b, x1)
        j, ok, _, chain_o = sc.shift(x_b, chain, x_c, x_bo, check=True)
        if not ok:
            continue
        n_ok += 1
        jb, okb, _, back = sc.shift(x_bo, chain_o, x_c, x_b)
        assert okb
        assert np.allclose(back, chain, atol=1e-9)
        assert j * jb == pytest.approx(1.0, rel=1e-7)
    assert n_ok >= 9


def test_irreversible_chain_is_flagged():
    """A configuration found by search (seed 3, tenth path on the glass sphere): the forward walk
    converges, the backward walk converges to a different chain; the check must say 'failed'."""
    sc, cfgs = _configs("sphere2", np.random.default_rng(3), 10)
    x_b, x1, x_bo = cfgs[9]
    chain, x_c = sc.trace_chain(x_b, x1)
    assert sc.shift(x_b, chain, x_c, x_bo)[1]
    _, ok_back_any, _, back = sc.shift(x_bo, sc.shift(x_b, chain, x_c, x_bo)[3], x_c, x_b, max_iter=30)
    assert not ok_back_any or not np.allclose(back, chain, atol=1e-6)
    assert not sc.shift(x_b, chain, x_c, x_bo, check=True)[1]


def test_jacobian_is_not_trivially_one():
    """Power: on the glass sphere the Jacobians differ from 1 by far more than the tolerance."""
    sc, cfgs = _configs("sphere2", np.random.default_rng(4), 10)
    js = [sc.shift(x_b, *sc.trace_chain(x_b, x1), x_bo)[0] for x_b, x1, x_bo in cfgs]
    assert np.mean(np.abs(np.array(js) - 1) > 1e-4) > 0.5


def test_unreachable_targets_fail_cleanly():
    # a small finite mirror: the offset's reflection point would be off the quad
    sc = mirror_scene(extent=0.05)
    x_b = np.array([0.0, 0.0, 3.0])
    x1 = np.array([0.04, 0.0, 0.0])
    chain, x_c = sc.trace_chain(x_b, x1)
    j, ok, it, _ = sc.shift(x_b, chain, x_c, x_b + [0.5, 0, 0])
    assert not ok and j == 0.0
    # the offset vertex moved behind the mirror: no reflection can join it to x_c
    sc = mirror_scene()
    chain, x_c = sc.trace_chain(x_b, x1)
    j, ok, it, _ = sc.shift(x_b, chain, x_c, np.array([0.0, 0.0, -0.5]))
    assert not ok and j == 0.0
    # a glass slab (two refractions) and an offset vertex 50 units away at grazing incidence: the
    # solution is far outside what 5 damped Newton steps from the base chain can reach
    top = Plane([0, 0, 0], [0, 0, 1])
    bottom = Plane([0, 0, -0.5], [0, 0, -1])
    sc = Scene([top, bottom], [M.plane_row([0, 0, 0], [0, 0, 1], [1, 0, 0]),
                               M.plane_row([0, 0, -0.5], [0, 0, -1], [1, 0, 0])],
               [True, True], Plane([0, 0, -0.6], [0, 0, 1]))
    x_b = np.array([0.0, 0.0, 1.0])
    chain, x_c = sc.trace_chain(x_b, np.array([0.2, 0.0, 0.0]))
    j, ok, it, _ = sc.shift(x_b, chain, x_c, np.array([-50.0, 0.0, 0.01]))
    assert not ok and j == 0.0
    # a far move that 5 iterations cannot reach, but more iterations can: the cap is honoured
    sc, cfgs = _configs("sphere2", np.random.default_rng(8), 1)
    x_b, x1, _ = cfgs[0]
    chain, x_c = sc.trace_chain(x_b, x1)
    far = x_b + [0.8, -0.6, 0.0]
    j1, ok1, it1, _ = sc.shift(x_b, chain, x_c, far, max_iter=1)
    assert not ok1 and it1 <= 1
    # degenerate inputs: zero chain length or an endpoint on the chain: flags, no exceptions
    j, ok, it, _ = sc.shift(x_b, chain, x_c, chain[0])
    assert not ok and np.isfinite(j)
    collapsed = np.zeros((2, 3))
    j, ok, it, _ = sc.shift(np.zeros(3), collapsed, np.zeros(3), np.zeros(3))
    assert not ok and j == 0.0
    j, ok, it, _ = sc.shift(x_b, chain, x_c, np.array([np.nan, 0.0, 0.0]))
    assert not ok and j == 0.0


def test_singular_system_is_reported():
    A = np.zeros((2, 2))
    B = np.ones((2, 1))
    assert not M.solve_linear(A, B, 2, 1)
    A = np.array([[2.0, 1.0], [1.0, 3.0]])
    B = np.array([[3.0], [5.0]])
    assert M.solve_linear(A.copy(), B, 2, 1)
    assert np.allclose(B[:, 0], np.linalg.solve(A, [3.0, 5.0]))


def _fd_derivatives(x_b, X, x_c, n_c, sc, targets, h=1e-5):
    """A = dC/dX and B = dC/dx_c by fourth-order central differences of M.constraints, each chain
    vertex moved in its own chart (M.shape_chart), x_c in the plane of normal n_c: the oracle of
    M.constraint_jacobian. Truncation ~h^4 |C^(5)| and round-off ~1e-16 / h: ~1e-11 here."""
    k, m = sc.k, 2 * sc.k
    se, te = np.array(M.vec.coordinate_system(T(n_c)))

    def c_at(j, a, d):
        Xp, xe = X.copy(), np.asarray(x_c, float)
        if j < k:
            Xp[j] = M.shape_chart(sc.rows, j, T(X[j]), d if a == 0 else 0.0, d if a == 1 else 0.0)
        else:
            xe = xe + (se if a == 0 else te) * d
        out = np.empty(m)
        assert M.constraints(T(x_b), Xp, T(xe), sc.rows, sc.etas, sc.refract, targets, k, out)
        return out

    cols = [(-c_at(j, a, 2 * h) + 8 * c_at(j, a, h) - 8 * c_at(j, a, -h) + c_at(j, a, -2 * h)) / (12 * h)
            for j in range(k + 1) for a in range(2)]
    D = np.array(cols).T
    return D[:, :m], D[:, m:]


@pytest.mark.parametrize("name", list(SCENES))
def test_constraint_derivatives_match_finite_differences(name):
    """M.constraint_jacobian's closed-form A = dC/dX and B = dC/dx_c against fourth-order central
    differences of the constraints (_fd_derivatives), on random base chains of every test scene
    and on the same chains moved off the solution (each vertex by up to 0.05 in its chart, so h is
    no longer the normal and a sphere's turning frame counts in full). Agreement is ~1e-10 of the
    largest entry; 1e-7 leaves three orders of margin and fails any missing term: a sphere's frame
    change dropped, the k factor of w_o, a sign of dw, or a neighbour's column (errors of order 1)."""
    rng = np.random.default_rng(7 + sum(map(ord, name)))
    sc, cfgs = _configs(name, rng, 10)
    checked = 0
    for x_b, x1, _ in cfgs:
        chain, x_c = sc.trace_chain(x_b, x1)
        k, m = sc.k, 2 * sc.k
        n_c = np.asarray(sc.end.normal(x_c), float)
        targets = np.zeros((k, 2))
        assert M.half_vector_targets(T(x_b), np.array(chain, float), T(x_c), sc.rows, sc.etas, sc.refract, k, targets)
        for off in (False, True):
            X = np.array(chain, float)
            if off:
                for j in range(k):
                    X[j] = M.shape_chart(sc.rows, j, T(X[j]), *rng.uniform(-0.05, 0.05, 2))
            A, B = np.empty((m, m)), np.empty((m, 2))
            if not M.constraint_jacobian(T(x_b), X, T(x_c), T(n_c), sc.rows, sc.etas, sc.refract, k, A, B, True):
                assert off, name                     # a base chain is always valid
                continue
            A_fd, B_fd = _fd_derivatives(x_b, X, x_c, n_c, sc, targets)
            scale = max(np.max(np.abs(A_fd)), np.max(np.abs(B_fd)))
            assert np.max(np.abs(A - A_fd)) <= 1e-7 * scale, (name, off)
            assert np.max(np.abs(B - B_fd)) <= 1e-7 * scale, (name, off)
            # without B, A alone is the same
            A2 = np.empty((m, m))
            assert M.constraint_jacobian(T(x_b), X, T(x_c), T(n_c), sc.rows, sc.etas, sc.refract, k, A2, A2, False)
            assert np.array_equal(A2, A)
            checked += 1
    assert checked >= 15, name


def _moved_end(sc, x_b, x1, step):
    """The base chain through x1 and, traced independently (numpy, the laws of reflection and
    refraction), the chain through x1 moved by ``step`` on its surface: (X, x_c, X', x_c')."""
    chain, x_c = sc.trace_chain(x_b, x1)
    moved = sc.trace_chain(x_b, sc.surfaces[0].chart(x1, *step))
    if moved is None:
        return None
    return np.array(chain, float), x_c, np.array(moved[0], float), moved[1]


def _sensitivity(sc, x_b, X, x_c):
    k, m = sc.k, 2 * sc.k
    targets = np.zeros((k, 2))
    assert M.half_vector_targets(T(x_b), X, T(x_c), sc.rows, sc.etas, sc.refract, k, targets)
    S = np.empty((m, 2))
    det, ok = M.endpoint_sensitivity(T(x_b), X, T(x_c), T(sc.end.normal(x_c)), sc.rows, sc.etas, sc.refract,
                                     targets, k, np.empty((m, m)), S)
    assert ok and det == pytest.approx(M.chain_endpoint_det(T(x_b), X, T(x_c), T(sc.end.normal(x_c)), sc.rows,
                                                            sc.etas, sc.refract, targets, k)[0], rel=1e-12)
    return targets, S


def moved_chains(name, seed, n):
    """``n`` configurations of scene ``name``, each with its end moved by a pixel-sized step (numpy's
    chains, :func:`_moved_end`): (scene, [(x_b, X, x_c, X', x_c', targets, S)]), S = A^-1 B at X."""
    rng = np.random.default_rng(seed)
    sc, cfgs = _configs(name, rng, n)
    out = []
    for x_b, x1, _ in cfgs:
        moved = _moved_end(sc, x_b, x1, rng.normal(size=2) * 0.02)
        if moved is not None:
            X, x_c, Xt, x_ct = moved
            out.append((x_b, X, x_c, Xt, x_ct) + _sensitivity(sc, x_b, X, x_c))
    return sc, out


@pytest.mark.parametrize("name", list(SCENES))
def test_predicted_start_is_first_order(name):
    """M.predicted_start moves the chain by -A^-1 B times the endpoint's move (the implicit function
    theorem): its error against the chain traced to the moved endpoint (numpy, independent of the
    code under test) must fall as the move squared. Halving the move divides the error by ~4 here
    (3 to 5.5 allows the next order's share); a wrong sign, a swapped column or a missed chart
    leaves an O(move) error, which halving only divides by 2."""
    rng = np.random.default_rng(11 + sum(map(ord, name)))
    sc, cfgs = _configs(name, rng, 8)
    ratios = []
    for x_b, x1, _ in cfgs:
        step = rng.normal(size=2) * 2e-3
        full, half = _moved_end(sc, x_b, x1, step), _moved_end(sc, x_b, x1, step / 2)
        if full is None or half is None:
            continue
        X, x_c = full[0], full[1]
        _, S = _sensitivity(sc, x_b, X, x_c)
        errs = []
        for _, _, Xt, x_ct in (full, half):
            Xp = np.empty_like(X)
            M.predicted_start(X, T(x_c), T(sc.end.normal(x_c)), T(x_ct), S, sc.rows, sc.k, Xp)
            errs.append(np.max(np.abs(Xp - Xt)))
            assert errs[-1] < 0.25 * np.max(np.abs(Xt - X)), name       # closer than the base chain
        ratios.append(errs[0] / errs[1])
    assert len(ratios) >= 6
    assert 3.0 < np.median(ratios) < 5.5, (name, ratios)


@pytest.mark.parametrize("name", list(SCENES))
def test_predicted_walk_finds_the_traced_chain_in_fewer_steps(name):
    """The walk from the predicted start (M.predicted_walk) reaches the chain the numpy tracer finds
    for a pixel-sized move of the endpoint (1e-9: the walk converges to |c| < 1e-12), in no more
    Newton steps than the walk from the base chain, and in fewer over all configurations."""
    sc, chains = moved_chains(name, 17 + sum(map(ord, name)), 10)
    steps_pred = steps_plain = 0
    for x_b, X, x_c, Xt, x_ct, targets, S in chains:
        Xo = np.empty_like(X)
        ok, it, _ = M.predicted_walk(T(x_b), X, T(x_c), T(sc.end.normal(x_c)), T(x_ct), S, sc.rows, sc.etas,
                                     sc.refract, targets, sc.k, Xo, None)
        Xw = X.copy()
        ok_w, it_w, _ = M.manifold_walk(T(x_b), T(x_ct), Xw, sc.rows, sc.etas, sc.refract, targets, sc.k,
                                        M.MAX_ITER, M.MAX_HALVINGS, M.TOL, None)
        if not ok_w:
            continue
        assert ok and np.allclose(Xo, Xt, atol=1e-9), name
        assert it <= it_w
        steps_pred, steps_plain = steps_pred + it, steps_plain + it_w
    assert steps_pred < steps_plain, (name, steps_pred, steps_plain)
