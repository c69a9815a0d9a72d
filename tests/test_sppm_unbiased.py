"""Fixed-radius unbiasedness of the surface photon density estimate.

With progression off (a fixed radius r) the estimate at a point p of a diffuse plane under a point
light is unbiased for the *blurred* radiance

    L_r(p) = rho / pi * 1 / (pi r^2) * int_{|x - p| < r} E(x) dA,   E(x) = I h / (h^2 + |x|^2)^1.5,

computed here independently with scipy. The estimate runs through the real pipeline: light paths
(gdlearn.photons.trace), the hash grid, and the gather kernel's photon sum
(gdlearn.integrators.photon.gather.density), normalised by the light paths *emitted*. The mean over
seeds must lie within 4 standard errors of L_r (false alarm ~6e-5 per point); a planted wrong
normalisation -- by the photons stored instead of the paths emitted, what PHOTONS.md Sec. 1.1 warns
about -- must fail the same check.
"""
import math
from pathlib import Path

import numpy as np
import pytest
from scipy import integrate

import gdlearn.scene
from gdlearn.integrators.photon.gather import GatherParams, density
from gdlearn.kernels.pathclass import ALL_MASK
from gdlearn.photons import grid as hashgrid
from gdlearn.photons.trace import LightTracer, TraceParams
from gdlearn.scene.compile import compile_scene

ROOT = Path(__file__).resolve().parent.parent
RHO, I, H, R = 0.5, 3.0, 1.0, 0.2
POINTS = [(0.0, 0.0), (0.6, -0.3), (1.2, 0.9)]
SEEDS, PATHS = 12, 20000


def _blurred(px, py, r):
    def f(rho, phi):
        x, y = px + rho * math.cos(phi), py + rho * math.sin(phi)
        return I * H / (H * H + x * x + y * y) ** 1.5 * rho
    e, _ = integrate.dblquad(f, 0.0, 2 * math.pi, 0.0, r, epsabs=1e-12, epsrel=1e-10)
    return RHO / math.pi * e / (math.pi * r * r)


def _estimates(normalise_by_stored=False):
    sa = compile_scene(gdlearn.scene.load(str(ROOT / "tests/scenes_photons/plane-point.xml")))
    tracer = LightTracer(sa, TraceParams(1, 5, 0.05, True, True))
    prm = GatherParams(2, 0.05, ALL_MASK, False)
    n = (0.0, 0.0, 1.0)
    frame = (n, (1.0, 0.0, 0.0), (0.0, 1.0, 0.0))
    out = np.zeros((SEEDS, len(POINTS)))
    for s in range(SEEDS):
        lp = tracer.trace(100 + s, 0, 0, PATHS)
        rows = lp.photons
        g = hashgrid.build(lp.pos[rows], R)
        g = g._replace(order=rows[g.order])
        norm = rows.size if normalise_by_stored else PATHS
        for k, (px, py) in enumerate(POINTS):
            gp = ((px, py, 0.0), n, frame, (0.0, 0.0, 1.0), sa.materials[0], 0, 0)
            phi, _ = density(lp, g, prm, gp, R)
            out[s, k] = phi[0] / (math.pi * R * R * norm)
    return out


def _z_scores(est):
    truth = np.array([_blurred(px, py, R) for px, py in POINTS])
    se = est.std(axis=0, ddof=1) / math.sqrt(est.shape[0])
    return (est.mean(axis=0) - truth) / se


def test_fixed_radius_estimate_is_unbiased_for_the_blurred_radiance():
    z = _z_scores(_estimates())
    assert np.all(np.abs(z) < 4.0), z


def test_a_wrong_normalisation_fails_the_same_check():
    z = _z_scores(_estimates(normalise_by_stored=True))
    assert np.any(np.abs(z) > 4.0), z
