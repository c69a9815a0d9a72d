"""MIS of forward/backward shifts (STAR Eq. 17) in ratio form, failed shifts (Sec. 3.5), the shift
policies and the path container."""
import math
from fractions import Fraction

import numpy as np
import pytest

from gdlearn.kernels import layout as L
from gdlearn.shifts import policy as P
from gdlearn.shifts.mis import (mis_weight, mis_weight_from_log_ratio, mis_weight_np,
                                mis_weight_products, shift_weights)
from gdlearn.shifts.path import (copy_path, fill_area_pdfs, geometry_term, new_path, set_vertex,
                                 solid_angle_to_area)


def exact_weight(pb, po, j):
    """Independent truth: Eq. 17 in exact rational arithmetic (no float range limits)."""
    pb, po, j = Fraction(pb), Fraction(po), Fraction(j)
    return float(pb / (pb + po * j))


@pytest.mark.parametrize("pb,po,j", [
    (1e-300, 1e-300, 1.0), (1e300, 1e300, 1.0), (1e-300, 1e300, 1.0), (1e300, 1e-300, 1.0),
    (1e-300, 3e-300, 0.5), (2e300, 1e300, 7.0), (1e-300, 1e-300, 1e300), (1e300, 1e300, 1e-300),
    (1.0, 1.0, 1.0), (0.3, 0.7, 2.0), (5e-324, 5e-324, 1.0),
])
def test_mis_extreme_densities(pb, po, j):
    w = mis_weight(pb, po, j)
    assert math.isfinite(w) and 0.0 <= w <= 1.0
    # 1e-13 relative: log/exp round-off of a ratio ~1 (a few ulps of log(1e300) ~ 690)
    assert w == pytest.approx(exact_weight(pb, po, j), rel=1e-12, abs=1e-300)


def test_naive_formula_would_fail_here():
    """The same inputs break the textbook expression: it is what the ratio form is for."""
    with np.errstate(all="ignore"):
        pb, po = np.float64(1e308), np.float64(1e308)
        assert pb / (pb + po * 10.0) == 0.0          # overflow to inf: the weight collapses to 0
        tb, to = np.float64(1e-200), np.float64(1e-200)
        assert np.isnan((tb * tb) / (tb * tb + to * to))   # 0 / 0: path densities underflow
    assert mis_weight(1e308, 1e308, 10.0) == pytest.approx(1 / 11, rel=1e-12)
    assert mis_weight(1e-200 * 1e-100, 1e-200 * 1e-100, 1.0) == pytest.approx(0.5, rel=1e-12)


def test_forward_and_backward_weights_sum_to_one():
    """For a reversible shift the backward strategy sees the offset path as its base, the inverse
    Jacobian and the roles of the densities swapped: both weights sum to 1 (a partition)."""
    rng = np.random.default_rng(0)
    for _ in range(200):
        pb, po = 10.0 ** rng.uniform(-300, 300, 2)
        j = 10.0 ** rng.uniform(-5, 5)
        # the backward shift evaluates the *same* pair of paths: p(T(x))|J| vs p(x)
        assert mis_weight(pb, po, j) + mis_weight(po * j, pb, 1.0) == pytest.approx(1.0, rel=1e-12)


def test_failed_shift_weights():
    assert shift_weights(1.0, 2.0, 1.0, False) == (1.0, 0.0)
    assert shift_weights(1.0, 1.0, 1.0, True) == (0.5, 0.5)
    # zero / NaN / negative offset density or Jacobian: base keeps weight 1, never NaN
    for po, j in ((0.0, 1.0), (1.0, 0.0), (np.nan, 1.0), (1.0, np.nan), (-1.0, 1.0)):
        assert mis_weight(1.0, po, j) == 1.0
    assert mis_weight(0.0, 1.0, 1.0) == 0.0
    assert mis_weight(np.nan, 1.0, 1.0) == 0.0
    assert mis_weight_from_log_ratio(np.inf) == 0.0
    assert mis_weight_from_log_ratio(-np.inf) == 1.0
    assert mis_weight_from_log_ratio(np.nan) == 1.0


def test_products_of_tiny_vertex_densities():
    # 40 vertices of density 1e-20 each: the products underflow to 0 in float64, the weight must not
    pb = np.full(40, 1e-20)
    po = np.full(40, 2e-20)
    w = mis_weight_products(pb, po, 40, math.log(1.0))
    assert w == pytest.approx(1.0 / (1.0 + 2.0 ** 40), rel=1e-10)
    assert np.prod(pb) == 0.0                      # what the naive product would have used
    assert mis_weight_products(pb, po, 40, -40 * math.log(2.0)) == pytest.approx(0.5, rel=1e-12)
    assert np.allclose(mis_weight_np([1.0, 1e300], [1.0, 1e300], [1.0, 3.0]), [0.5, 0.25])


# --- policies -----------------------------------------------------------------------------------

D, G, S, M = L.V_DIFFUSE, L.V_GLOSSY, L.V_SPECULAR, L.V_MEDIUM


def _vc(*c):
    return np.array(c, np.int32)


def test_policy_choices():
    path = _vc(D, D, D)                    # sensor (counted connectable), diffuse, diffuse
    assert P.choose_shift(P.POLICY_REPLAY, D, D, path, 1, 3) == P.SHIFT_REPLAY
    for pol in (P.POLICY_REPLAY_RECONNECTION, P.POLICY_HALFVECTOR_RECONNECTION):
        assert P.choose_shift(pol, D, D, path, 1, 3) == P.SHIFT_RECONNECT
    chain = _vc(D, D, S, S, D)
    assert P.choose_shift(P.POLICY_REPLAY_RECONNECTION, D, D, chain, 1, 5) == P.SHIFT_REPLAY
    assert P.choose_shift(P.POLICY_HALFVECTOR_RECONNECTION, D, D, chain, 1, 5) == P.SHIFT_HALFVECTOR
    assert P.choose_shift(P.POLICY_HALFVECTOR_RECONNECTION_MANIFOLD, D, D, chain, 1, 5) == P.SHIFT_MANIFOLD
    # a chain longer than MAX_CHAIN, or one that never reaches a connectable vertex: half-vector copy
    long_chain = _vc(D, D, S, S, S, S, D)
    assert P.choose_shift(P.POLICY_HALFVECTOR_RECONNECTION_MANIFOLD, D, D, long_chain, 1, 7) == P.SHIFT_HALFVECTOR
    open_chain = _vc(D, D, S, S)
    assert P.choose_shift(P.POLICY_HALFVECTOR_RECONNECTION_MANIFOLD, D, D, open_chain, 1, 4) == P.SHIFT_HALFVECTOR
    # base and offset classes disagree: Kettunen et al.'s rule fails; replay and the mixed policies replay
    assert P.choose_shift(P.POLICY_HALFVECTOR_RECONNECTION, D, S, path, 1, 3) == P.SHIFT_FAIL
    for pol in (P.POLICY_REPLAY, P.POLICY_REPLAY_RECONNECTION, P.POLICY_HALFVECTOR_REPLAY_RECONNECTION):
        assert P.choose_shift(pol, D, S, path, 1, 3) == P.SHIFT_REPLAY
        assert P.choose_shift(pol, S, D, path, 1, 3) == P.SHIFT_REPLAY
    # the mixed half-vector policy copies half vectors only where both vertices are not connectable
    assert P.choose_shift(P.POLICY_HALFVECTOR_REPLAY_RECONNECTION, D, D, chain, 1, 5) == P.SHIFT_REPLAY
    assert P.choose_shift(P.POLICY_HALFVECTOR_REPLAY_RECONNECTION, S, S, chain, 2, 5) == P.SHIFT_HALFVECTOR
    assert P.choose_shift(P.POLICY_HALFVECTOR_REPLAY_RECONNECTION, D, D, path, 1, 3) == P.SHIFT_RECONNECT
    # glossy and medium vertices reconnect like diffuse ones
    assert P.choose_shift(P.POLICY_HALFVECTOR_RECONNECTION, G, M, _vc(D, G, M), 1, 3) == P.SHIFT_RECONNECT
    # last vertex (next-event estimation): reconnect from a connectable vertex only
    assert P.choose_shift(P.POLICY_HALFVECTOR_RECONNECTION, D, D, _vc(D, D), 1, 2) == P.SHIFT_RECONNECT
    assert P.choose_shift(P.POLICY_HALFVECTOR_RECONNECTION, S, S, _vc(D, S), 1, 2) == P.SHIFT_HALFVECTOR
    assert P.choose_shift(P.POLICY_REPLAY_RECONNECTION, S, S, _vc(D, S), 1, 2) == P.SHIFT_REPLAY
    assert P.choose_shift(P.POLICY_REPLAY, D, D, _vc(D, D), 1, 2) == P.SHIFT_REPLAY
    assert P.policy_code("halfvector+reconnection") == P.POLICY_HALFVECTOR_RECONNECTION
    with pytest.raises(ValueError, match="fix: use one of"):
        P.policy_code("halfvector")


def test_stats_counting():
    st = P.new_stats()
    P.record(st, P.SHIFT_RECONNECT, True)
    P.record(st, P.SHIFT_RECONNECT, False)
    P.record(st, P.SHIFT_MANIFOLD, False)
    d = P.stats_dict(st)
    assert d["reconnection"] == {"run": 2, "ok": 1, "failed": 1}
    assert d["manifold"] == {"run": 1, "ok": 0, "failed": 1}
    assert d["halfvector"]["run"] == 0


# --- path container -----------------------------------------------------------------------------

def test_path_arrays_and_area_pdfs():
    path = new_path(3)
    set_vertex(path, 0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), -1, -1, D, 0.5)
    set_vertex(path, 1, (0.0, 0.0, 2.0), (0.0, 0.0, -1.0), (0.0, 0.0, -1.0), 3, -1, S, 0.25)
    set_vertex(path, 2, (0.0, 3.0, 2.0), (0.0, 1.0, 0.0), (0.0, 1.0, 0.0), 1, 0, D, 0.0)
    fill_area_pdfs(path, 3)
    # hand-computed: 0.5 * |cos 0| / 2^2 and 0.25 * |cos 0| / 3^2
    assert path[7][0] == pytest.approx(0.5 / 4) and path[7][1] == pytest.approx(0.25 / 9)
    assert path[7][2] == 0.0
    other = new_path(3)
    copy_path(path, other, 3)
    for a, b in zip(path, other):
        assert np.array_equal(a, b)
    # 45-degree geometry: G = cos45 cos45 / 2
    assert geometry_term((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), (1.0, 0.0, 1.0), (-1.0, 0.0, 0.0)) == pytest.approx(0.25)
    assert solid_angle_to_area(1.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0)) == 0.0
    with pytest.raises(ValueError, match="fix"):
        new_path(0)
