"""Tests of the exercise "mis-weights". Each docstring is the line `gdlearn check` prints.

The reference values are computed here by hand or in plain floating point where that is exact
enough; the last test builds a 1-D gradient-domain estimator around the two functions and compares
its Monte Carlo estimate (fixed seed) with the exact pixel difference.
"""
import math

import numpy as np
import pytest

from gdlearn.teaching.exercises import load_target

ex = load_target("mis-weights")


def w(p, q, j):
    return ex.balance_weight(math.log(p), math.log(q), math.log(j))


def test_hand_values():
    """balance_weight: p / (p + p' |J|) for simple numbers (1/2, 3/4, 1/4, 0.9)"""
    assert math.isclose(w(1.0, 1.0, 1.0), 0.5, rel_tol=1e-12), "equal densities, J = 1: weight 1/2"
    assert math.isclose(w(3.0, 1.0, 1.0), 0.75, rel_tol=1e-12), "p = 3, p' = 1, J = 1: weight 3/4"
    assert math.isclose(w(1.0, 1.5, 2.0), 0.25, rel_tol=1e-12), "p = 1, p' = 1.5, J = 2: weight 1/4"
    assert math.isclose(w(0.9, 0.2, 0.5), 0.9, rel_tol=1e-12), "p = 0.9, p' |J| = 0.1: weight 0.9"


def test_extreme_densities():
    """balance_weight: densities of 1e-300 and 1e+300 (products of long paths) give finite, right weights"""
    tiny, huge = math.log(1e-300), math.log(1e300)
    got = ex.balance_weight(tiny, tiny, 0.0)
    assert math.isclose(got, 0.5, rel_tol=1e-12), f"p = p' = 1e-300: expected 1/2, got {got}"
    got = ex.balance_weight(huge, tiny, 0.0)
    assert got == 1.0 or math.isclose(got, 1.0, rel_tol=1e-15), f"p = 1e300 >> p' = 1e-300: expected 1, got {got}"
    got = ex.balance_weight(tiny, huge, 0.0)
    assert 0.0 <= got < 1e-300, f"p = 1e-300 << p' = 1e300: expected ~0 (1e-600 underflows to 0), got {got}"
    # a 200-vertex path: products of 200 densities of 1e-3 and 2e-3 would underflow to 0 / 0
    got = ex.balance_weight(200 * math.log(1e-3), 200 * math.log(2e-3), 0.0)
    assert 0.0 <= got <= 1e-59 and math.isfinite(got), f"(1e-3)^200 vs (2e-3)^200: expected 1/(1+2^200), got {got}"
    assert math.isclose(got, 1 / (1 + 2.0 ** 200), rel_tol=1e-9), f"expected 1/(1+2^200) = {1 / (1 + 2.0 ** 200):.3e}, got {got:.3e}"


def test_infinite_log_ratios():
    """balance_weight: an offset that cannot be sampled (log p' = -inf) gets weight 1, and no NaN ever"""
    assert ex.balance_weight(0.0, -math.inf, 0.0) == 1.0, "log p' = -inf: the offset density is 0, weight 1"
    assert ex.balance_weight(-math.inf, 0.0, 0.0) == 0.0, "log p = -inf: the base density is 0, weight 0"
    got = ex.balance_weight(0.0, 0.0, math.inf)
    assert got == 0.0, f"an infinite Jacobian: weight 0, got {got}"


@pytest.mark.parametrize("seed", range(5))
def test_forward_and_backward_weights_sum_to_one(seed):
    """balance_weight: for an invertible shift the forward and the backward weight of a pair sum to 1"""
    rng = np.random.default_rng(seed)
    for _ in range(200):
        lp, lq, lj = rng.normal(0, 30, 3)          # densities over 1e+-40, Jacobians too
        fwd = ex.balance_weight(lp, lq, lj)
        # the backward shift starts from the offset (density p'), its Jacobian is 1/J
        bwd = ex.balance_weight(lq, lp, -lj)
        assert math.isclose(fwd + bwd, 1.0, rel_tol=1e-12, abs_tol=1e-12), \
            f"log p = {lp:.2f}, log p' = {lq:.2f}, log J = {lj:.2f}: w_pq + w_qp = {fwd + bwd}, not 1"


def test_replay_gives_one_half():
    """balance_weight: under replay |J| = p(x) / p(x'), so the weight is exactly 1/2 whatever the densities"""
    for lp, lq in ((0.0, 0.0), (-5.0, 3.0), (-700.0, 650.0), (123.0, -456.0)):
        got = ex.balance_weight(lp, lq, lp - lq)
        assert math.isclose(got, 0.5, rel_tol=1e-12), f"log p = {lp}, log p' = {lq}, J = p/p': expected 1/2, got {got}"


def test_forward_contribution_and_failure():
    """forward_contribution: weight * (f' J - f) / p, and a failed shift enters with weight 1 and no offset"""
    got = ex.forward_contribution(2.0, 0.5, 3.0, 2.0, 0.25, False)
    assert math.isclose(got, 0.25 * (3.0 * 2.0 - 2.0) / 0.5, rel_tol=1e-12), f"expected 2.0, got {got}"
    got = ex.forward_contribution(2.0, 0.5, 3.0, 2.0, 0.25, True)
    assert math.isclose(got, -4.0, rel_tol=1e-12), \
        f"a failed shift: expected -f / p = -4.0 (weight 1, no offset), got {got}"


def test_two_way_estimate_is_unbiased():
    """both functions together estimate a 1-D pixel difference without bias (Monte Carlo, fixed seed)"""
    # Pixels are unit intervals on a line; "paths" are points x with the integrand g. Pixel p = [0, 1)
    # samples x with the density p_p(x) = 2x, pixel q = [1, 2) uniformly (p_q = 1): the two pixels
    # sample differently, so the weights are not 1/2. The shift T(x) = x + 1 has |J| = 1. Pairs whose
    # point in q has g below 1.5 are declared failed (as if a visibility test had failed), which the
    # estimator must survive without bias.
    g = lambda x: 1.0 + np.sin(3.0 * x) + 0.5 * x * x
    exact = (lambda a, b: (b - a) - (np.cos(3 * b) - np.cos(3 * a)) / 3 + (b ** 3 - a ** 3) / 6)
    delta = exact(1.0, 2.0) - exact(0.0, 1.0)
    rng = np.random.default_rng(7)
    n = 100000
    total, n_failed = 0.0, 0
    for xp, xq in zip(np.sqrt(rng.random(n)), 1.0 + rng.random(n)):
        # forward: base x in p (density 2x), offset x + 1 in q (density 1)
        failed = g(xp + 1) < 1.5
        wf = ex.balance_weight(math.log(2 * xp), 0.0, 0.0)
        total += ex.forward_contribution(g(xp), 2 * xp, g(xp + 1), 1.0, wf, failed)
        # backward: base x in q (density 1), offset x - 1 in p (density 2(x - 1)); its term is
        # weight * (f - f' J) / p, the negative of a forward contribution
        failed = g(xq) < 1.5
        n_failed += failed
        wb = ex.balance_weight(0.0, math.log(2 * (xq - 1)), 0.0)
        total -= ex.forward_contribution(g(xq), 1.0, g(xq - 1), 1.0, wb, failed)
    est = total / n
    assert n_failed > 0.1 * n, "test set-up: the failure region should be hit"
    assert abs(est - delta) < 0.02, f"two-way estimate {est:.4f}, exact difference {delta:.4f}"
