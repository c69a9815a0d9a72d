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
from gdlearn.kernels.lights import spot_falloff
from gdlearn.kernels.pathclass import ALL_MASK
from gdlearn.photons import grid as hashgrid
from gdlearn.photons.trace import LightTracer, TraceParams
from gdlearn.scene.compile import compile_scene

ROOT = Path(__file__).resolve().parent.parent
RHO, I, H, R = 0.5, 3.0, 1.0, 0.2
POINTS = [(0.0, 0.0), (0.6, -0.3), (1.2, 0.9)]
#: inside the spot's 40 degree cone (radius tan 40 ~ 0.84 on the plane), one disc across its falloff
SPOT_POINTS = [(0.0, 0.0), (0.3, -0.2), (0.55, 0.3)]
SEEDS, PATHS = 12, 20000


EMITTERS = {
    "spot": f'''<emitter type="spot"><transform name="to_world"><lookat origin="0, 0, {H}" target="0, 0, 0"
               up="0, 1, 0"/></transform><rgb name="intensity" value="{I}"/>
               <float name="cutoff_angle" value="40"/></emitter>''',
    "directional": f'<emitter type="directional"><vector name="direction" x="0" y="0" z="-1"/>'
                   f'<rgb name="irradiance" value="{I}"/></emitter>',
    "constant": f'<emitter type="constant"><rgb name="radiance" value="{I}"/></emitter>',
}


def _scene(kind, tmp_path):
    path = ROOT / "tests/scenes_photons/plane-point.xml"
    if kind == "point":
        return compile_scene(gdlearn.scene.load(str(path)))
    text = path.read_text()
    a, b = text.index("<emitter"), text.index("</emitter>") + len("</emitter>")
    out = tmp_path / f"plane-{kind}.xml"
    out.write_text(text[:a] + EMITTERS[kind] + text[b:])
    return compile_scene(gdlearn.scene.load(str(out)))


def _irradiance(kind, sa):
    if kind == "directional":
        return lambda x, y: I
    if kind == "constant":
        return lambda x, y: math.pi * I
    falloff = (lambda d: 1.0) if kind == "point" else (lambda d: spot_falloff.py_func(sa.emitters, 0, d))

    def e(x, y):
        d2 = H * H + x * x + y * y
        dv = (x / math.sqrt(d2), y / math.sqrt(d2), -H / math.sqrt(d2))
        return I * H / d2 ** 1.5 * falloff(dv)
    return e


def _blurred(e, px, py, r):
    def f(rho, phi):
        return e(px + rho * math.cos(phi), py + rho * math.sin(phi)) * rho
    # the spot's falloff has kinks: 1e-7 relative is far below the estimates' ~1 % standard errors
    v, _ = integrate.dblquad(f, 0.0, 2 * math.pi, 0.0, r, epsabs=1e-10, epsrel=1e-7)
    return RHO / math.pi * v / (math.pi * r * r)


def _estimates(sa, normalise_by_stored=False, points=POINTS):
    tracer = LightTracer(sa, TraceParams(1, 5, 0.05, True, True))
    prm = GatherParams(2, 0.05, ALL_MASK, False)
    n = (0.0, 0.0, 1.0)
    frame = (n, (1.0, 0.0, 0.0), (0.0, 1.0, 0.0))
    out = np.zeros((SEEDS, len(points)))
    for s in range(SEEDS):
        lp = tracer.trace(100 + s, 0, 0, PATHS)
        rows = lp.photons
        g = hashgrid.build(lp.pos[rows], R)
        g = g._replace(order=rows[g.order])
        norm = rows.size if normalise_by_stored else PATHS
        for k, (px, py) in enumerate(points):
            gp = ((px, py, 0.0), n, frame, (0.0, 0.0, 1.0), sa.materials[0], 0, 0)
            phi, _ = density(lp, g, prm, gp, R)
            out[s, k] = phi[0] / (math.pi * R * R * norm)
    return out


def _z_scores(est, sa, kind="point", points=POINTS):
    e = _irradiance(kind, sa)
    truth = np.array([_blurred(e, px, py, R) for px, py in points])
    se = est.std(axis=0, ddof=1) / math.sqrt(est.shape[0])
    return (est.mean(axis=0) - truth) / se


@pytest.mark.parametrize("kind", ["point", "spot", "directional", "constant"])
def test_fixed_radius_estimate_is_unbiased_for_the_blurred_radiance(kind, tmp_path):
    sa = _scene(kind, tmp_path)
    pts = SPOT_POINTS if kind == "spot" else POINTS
    z = _z_scores(_estimates(sa, points=pts), sa, kind, pts)
    assert np.all(np.abs(z) < 4.0), z


def test_a_wrong_normalisation_fails_the_same_check(tmp_path):
    sa = _scene("point", tmp_path)
    z = _z_scores(_estimates(sa, normalise_by_stored=True), sa)
    assert np.any(np.abs(z) > 4.0), z
