"""GPM's manifold branch (Hua et al. 2017 Eq. 7-8) through glass: the two refractions of the ball
lens of scenes/caustic-closeup.xml (k = 2), against an independent construction, as
tests/test_gpm_manifold.py does for the mirror. For a light path y_b (on the light) -> y_{b+1}
(entering the ball) -> y_{b+2} (leaving it) -> y_s (on the floor) and a target y* near y_s on the
floor, the two points on the sphere that join y_b to y* by Snell's law at both are found by scipy's
root finder, so neither the offset chain nor the Jacobian |d omega' / d omega| of the direction
leaving y_b (central differences of that solver) comes from gdlearn's walk; the lobe probabilities
(the Fresnel transmittances) are computed here from the Fresnel equations.

PHOTONS.md T2/T4: the walk finds the solver's chain, its Jacobian equals the finite-difference
one, the inverse shift (from the offset light path built from the solver's chain) succeeds exactly
when the forward one does, and the two density ratios and power ratios are reciprocal, so
w(x) + w(T x) = 1 for every pair.
"""
from __future__ import annotations

import warnings
from typing import NamedTuple

import numpy as np
import pytest
from scipy.optimize import fsolve

from gdlearn.integrators import make
from gdlearn.integrators.photon.gpm_light import parent_factor
from gdlearn.integrators.photon.photon_manifold import manifold_photon
from gdlearn.kernels.accel.bvh import STACK_SIZE
from gdlearn.photons.records import F_DELTA_OUT, K_EMITTER, K_SURFACE
from gdlearn.scene.load import load



class Ball(NamedTuple):
    """A smooth dielectric sphere in vacuum: the solver's only geometry."""
    center: np.ndarray
    radius: float
    eta: float


LENS = Ball(np.array([0.0, 0.55, 0.0]), 0.33, 1.5)     # the ball of scenes/caustic-closeup.xml
#: a large kernel: only the map decides (see tests/test_gpm_manifold.py)
R_KERNEL = 10.0


def _unit(a):
    return a / np.linalg.norm(a)


def _tangent(u):
    a = _unit(np.cross(u, [0.3, 0.5, 0.7]))
    return a, np.cross(u, a)


def _glass_chain(ball, yb, y, m1, m2):
    """The entry and exit points (near m1, m2) where light from yb refracts into the ball and out
    to y, or None. Unknowns: each point's normal in the tangent plane of its initial normal (a chart
    per vertex); residuals: the tangential part of eta_a w_a + eta_b w_b at each vertex (Snell's
    law, w the unit directions towards the chain's neighbours)."""
    charts = [(_unit(m - ball.center),) + _tangent(_unit(m - ball.center)) for m in (m1, m2)]

    def points(p):
        return [ball.center + ball.radius * _unit(u0 + p[2 * i] * e1 + p[2 * i + 1] * e2)
                for i, (u0, e1, e2) in enumerate(charts)]

    def residual(p):
        a, b = points(p)
        res = []
        for m, prev, nxt, eta_prev, eta_next in ((a, yb, b, 1.0, ball.eta), (b, a, y, ball.eta, 1.0)):
            v = eta_prev * _unit(prev - m) + eta_next * _unit(nxt - m)
            t1, t2 = _tangent(_unit(m - ball.center))
            res += [v @ t1, v @ t2]
        return res
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        sol = fsolve(residual, np.zeros(4), xtol=1e-14)
    return points(sol) if np.abs(residual(sol)).max() < 1e-12 else None


def _fresnel_transmittance(ball, w, m, eta_from, eta_to):
    """1 - F of the unpolarised Fresnel equations for light arriving at m along w (travel)."""
    ci = abs(w @ _unit(m - ball.center))
    eta = eta_to / eta_from
    st2 = (1.0 - ci * ci) / (eta * eta)
    ct = np.sqrt(1.0 - st2)
    rs = (ci - eta * ct) / (ci + eta * ct)
    rp = (eta * ci - ct) / (eta * ci + ct)
    return 1.0 - 0.5 * (rs * rs + rp * rp)


def _lobe_probabilities(ball, yb, m1, m2):
    """The product of the two refractions' discrete lobe probabilities (Mitsuba's dielectric picks
    refraction with probability 1 - F)."""
    return (_fresnel_transmittance(ball, _unit(m1 - yb), m1, 1.0, ball.eta)
            * _fresnel_transmittance(ball, _unit(m2 - m1), m2, ball.eta, 1.0))


def _solid_angle_per_area(yb, y, n, m1, m2, h=1e-5):
    """|d omega / dA_y| of the direction yb -> entry point as y moves on its plane (normal n)."""
    s = _unit(np.cross(n, [0.3, 0.5, 0.7]))
    t = np.cross(n, s)
    w = lambda yy: _unit(_glass_chain(LENS, yb, yy, m1, m2)[0] - yb)
    ws = (w(y + h * s) - w(y - h * s)) / (2 * h)
    wt = (w(y + h * t) - w(y - h * t)) / (2 * h)
    return abs(np.cross(ws, wt) @ w(y))


def _on_ball(ball, p):
    return abs(np.linalg.norm(p - ball.center) - ball.radius) < 1e-6


def _lens_photons(lp):
    """Photon rows v on the floor whose chain is light -> entry -> exit: (v, exit q, entry q2, light b).
    A chord between two points of a sphere runs inside it, so entry and exit are refractions."""
    for v in range(len(lp)):
        q = lp.parent[v]
        if q < 0 or lp.kind[v] != K_SURFACE or lp.kind[q] != K_SURFACE or not lp.flags[q] & F_DELTA_OUT:
            continue
        q2 = lp.parent[q]
        if q2 < 0 or lp.kind[q2] != K_SURFACE or not lp.flags[q2] & F_DELTA_OUT:
            continue
        b = lp.parent[q2]
        if b >= 0 and lp.kind[b] == K_EMITTER and _on_ball(LENS, lp.pos[q]) and _on_ball(LENS, lp.pos[q2]):
            yield v, q, q2, b


@pytest.fixture(scope="module")
def lens_paths():
    g = make("gpm", load("scenes/caustic-closeup.xml", res=8), photons_per_pass=100)
    return g, g.tracer.trace(5, 0, 0, 20_000)


def _offset_light_path(ball, lp, v, q, q2, yb, m1, m2, ystar):
    """The light path of the offset photon, built from the solver's chain."""
    off = type(lp)(*(f.copy() for f in lp))
    off.pos[q2], off.pos[q], off.pos[v] = m1, m2, ystar
    off.d_in[q2], off.d_in[q], off.d_in[v] = _unit(m1 - yb), _unit(m2 - m1), _unit(ystar - m2)
    off.nrm[q2] = off.nsh[q2] = _unit(m1 - ball.center)
    off.nrm[q] = off.nsh[q] = _unit(m2 - ball.center)
    return off


def test_walk_through_glass_against_an_independent_solver(lens_paths):
    """Up to 300 photons under the ball, each moved by up to 4 mm on the floor (the caustic is a few
    mm wide: larger moves mostly leave it and the walk, rightly, fails): the inverse shift succeeds
    iff the forward one does; the density and power ratios of a pair are reciprocal to the
    determinants' truncation error (3e-4, as for the mirror); for 12 pairs the density ratio equals
    the emitter's ratio times the solver's finite-difference Jacobian in the solid angle at y_b
    times the ratio of the Fresnel transmittances (rel 1e-5: central differences on both sides)."""
    g, lp = lens_paths
    sa, stack = g.setup.sa, np.empty(STACK_SIZE, np.int32)
    rng = np.random.default_rng(2)
    counts = {"both": 0, "one way": 0, "neither": 0}
    jac_checked = 0
    for v, q, q2, b in _lens_photons(lp):
        yb, ys, n = lp.pos[b].copy(), lp.pos[v].copy(), lp.nrm[v].copy()
        x1, x2 = lp.pos[q2].copy(), lp.pos[q].copy()
        s = _unit(np.cross(n, [0.3, 0.5, 0.7]))
        ystar = ys + rng.uniform(-0.004, 0.004) * s + rng.uniform(-0.004, 0.004) * np.cross(n, s)
        chain = _glass_chain(LENS, yb, ystar, x1, x2)
        if chain is None or max(np.linalg.norm(chain[0] - x1), np.linalg.norm(chain[1] - x2)) > 0.1:
            continue
        m1, m2 = chain
        ok_f, r3_f, pp_f, _ = manifold_photon(sa, lp, g.mtab, g.gather_params, v, q, tuple(ystar), tuple(n),
                                              R_KERNEL, tuple(ystar), stack)
        off = _offset_light_path(LENS, lp, v, q, q2, yb, m1, m2, ystar)
        ok_r, r3_r, pp_r, _ = manifold_photon(sa, off, g.mtab, g.gather_params, v, q, tuple(ys), tuple(n),
                                              R_KERNEL, tuple(ys), stack)
        counts["both" if ok_f and ok_r else "one way" if ok_f != ok_r else "neither"] += 1
        if ok_f and ok_r:
            assert pp_f * pp_r == pytest.approx(1.0, abs=3e-4)
            assert np.allclose(np.array(r3_f) * np.array(r3_r), 1.0, atol=3e-4)
            if jac_checked < 12:
                _, fr, pr = parent_factor(sa, lp, b, q2, tuple(_unit(m1 - yb)))
                fd = _solid_angle_per_area(yb, ystar, n, m1, m2) / _solid_angle_per_area(yb, ys, n, x1, x2)
                lobes = _lobe_probabilities(LENS, yb, m1, m2) / _lobe_probabilities(LENS, yb, x1, x2)
                assert pp_f == pytest.approx(pr * fd * lobes, rel=1e-5), v
                # the power: the emitter's profile, the Jacobian, and the two refractions' values
                # (1 - F each; the radiance scaling by eta is the same on both sides and cancels)
                assert np.allclose(r3_f, np.array(fr) * fd * lobes, rtol=1e-5), v
                jac_checked += 1
        if sum(counts.values()) >= 300:
            break
    assert counts["one way"] == 0, counts
    assert counts["both"] > 150 and jac_checked == 12, counts
