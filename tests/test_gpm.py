"""Gradient-domain photon mapping (Hua et al. 2017): the base estimate is SPPM's, the gradients are
unbiased at a fixed radius, the shifts succeed often enough to matter and lower the gradients'
variance, Eq. 6 against finite differences, and the refusals."""
from __future__ import annotations

import math

import numpy as np
import pytest

from gdlearn.integrators import make
from gdlearn.integrators.base import render
from gdlearn.scene.load import load
from gdlearn.shifts.photon import offset_target, projection_jacobian
from conftest import gradient_residuals

#: a fixed radius for every pixel and no reduction (alpha = 1): each pass is an independent estimate
#: of the image blurred by r, and the gradients must be unbiased for its differences
FIXED = dict(photons_per_pass=20_000, radius=0.08, alpha=1.0)
N_SEEDS = 24


@pytest.fixture(scope="module")
def cornell():
    return load("scenes/cornell-box.xml", res=16)


@pytest.fixture(scope="module")
def runs(cornell):
    """Per seed: (gx - FD(base), gy - FD(base), primal - base, gx, FD_x(base)) channel means."""
    out = []
    for seed in range(N_SEEDS):
        f = render(make("gpm", cornell, seed=500 + seed, **FIXED), spp=16)
        out.append(gradient_residuals(f))
        last = f
    return np.array(out), last


def test_base_estimate_is_sppm(cornell):
    """The base buffer is exactly SPPM's estimate for the same seed (same photons, same gather
    points): GPM's primal rests on the estimator tests/test_sppm_mitsuba.py checks against Mitsuba."""
    g = render(make("gpm", cornell, seed=3, **FIXED), spp=4)
    s = render(make("sppm", cornell, seed=3, **FIXED), spp=4)
    assert np.array_equal(g.images["primal_base"], s.primal)
    assert s.primal.mean() > 0.05


def _z(d):
    m = d.mean(0)
    se = d.std(0, ddof=1) / math.sqrt(len(d))
    ok = se > 1e-12
    return m[ok] / se[ok]


@pytest.mark.parametrize("i,name", [(0, "gx"), (1, "gy"), (2, "primal")])
def test_unbiased_at_fixed_radius(runs, i, name):
    """gx - (I[x+1] - I[x]) (and gy, and the MIS primal - the base) has mean zero per pixel: the
    paired difference cancels most photon noise, so this resolves biases far below the noise of
    either image. Over 24 seeds z is Student-t with 23 degrees of freedom: E z^2 = 23/21 = 1.10;
    1.45 leaves room for the heavier tails of a few corner pixels, and |z| > 5.5 has probability
    ~1e-5 per pixel. Dropping the MIS weight (w = 1 both ways), the parent's BSDF ratio, or the
    reversibility check fails it."""
    d, _ = runs
    z = _z(d[:, i])
    assert z.size > 150, "too few pixels with a spread: the shifts or the photons are missing"
    assert (z ** 2).mean() < 1.45, f"{name}: mean z^2 {(z ** 2).mean():.2f} (max |z| {np.abs(z).max():.1f})"
    assert np.abs(z).max() < 5.5


def test_shifts_succeed_and_lower_the_variance(runs):
    """Two thirds of the photon shifts reconnect on the Cornell box (all-diffuse, so none needs the manifold walk),
    and the gradient is less noisy than the difference of two primal estimates -- the reason for
    gradient-domain rendering. Failing every shift would pass the unbiasedness test trivially; this
    one would then fail (ratio 1)."""
    d, last = runs
    n_ok, n_fail = last.images["shift_reconnected"].sum(), last.images["shift_failed"].sum()
    assert n_ok > 2 * n_fail          # at 16 x 16 a pixel is wide: borders and edges fail many
    assert last.images["shift_manifold"].sum() == 0           # no specular shapes
    interior = (slice(None), slice(2, -2), slice(2, -3))
    ratio = d[:, 3][interior].var(axis=0).mean() / d[:, 4][interior].var(axis=0).mean()
    assert ratio < 0.5, f"var(gx) / var(FD of the primal) = {ratio:.2f}"


def test_projection_jacobian_against_finite_differences():
    """Eq. 6: the area change of projecting a small patch around y* (in the plane of normal n*) from
    the parent onto a sphere, measured by finite differences of the ray-sphere hit, against
    (cos* / d*^2) / (cos' / d'^2). Planting cos' for cos* (or dropping a square) fails it."""
    c, rad = np.array([0.0, 0.0, 0.0]), 1.0
    yq = np.array([0.3, -0.4, 3.0])
    ystar = np.array([0.2, 0.1, 1.15])
    nstar = np.array([0.3, 0.2, 1.0]) / np.linalg.norm([0.3, 0.2, 1.0])

    def hit(p):
        d = (p - yq) / np.linalg.norm(p - yq)
        b = np.dot(yq - c, d)
        t = -b - math.sqrt(b * b - (np.dot(yq - c, yq - c) - rad * rad))
        return yq + t * d

    e1 = np.cross(nstar, [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(nstar, e1)
    eps = 1e-6
    a = (hit(ystar + eps * e1) - hit(ystar - eps * e1)) / (2 * eps)
    b = (hit(ystar + eps * e2) - hit(ystar - eps * e2)) / (2 * eps)
    fd = np.linalg.norm(np.cross(a, b))
    yh = hit(ystar)
    nh = (yh - c) / rad
    j = projection_jacobian(tuple(yq), tuple(ystar), tuple(nstar), tuple(yh), tuple(nh))
    assert j == pytest.approx(fd, rel=1e-6)


def test_offset_target_is_a_rigid_copy():
    """Eq. 5 keeps the distance to the gather point and, for equal frames, is a translation."""
    n = (0.0, 0.0, 1.0)
    s, t = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)
    y, z, z2 = (0.3, 0.1, 0.0), (0.25, 0.05, 0.0), (0.5, -0.2, 0.0)
    got = offset_target(y, z, (n, s, t), z2, (n, s, t))
    assert np.allclose(got, np.array(y) - np.array(z) + np.array(z2))
    n2 = (0.0, 1.0, 0.0)
    got = offset_target(y, z, (n, s, t), z2, (n2, (1.0, 0.0, 0.0), (0.0, 0.0, -1.0)))
    assert np.linalg.norm(np.array(got) - z2) == pytest.approx(np.linalg.norm(np.array(y) - z))
    assert abs(np.dot(np.array(got) - z2, n2)) < 1e-15      # stays in the offset's tangent plane


def test_refusals(cornell):
    with pytest.raises(ValueError, match="direct"):
        make("gpm", cornell, direct="nee")
    with pytest.raises(ValueError, match="vpm or bre"):
        make("gpm", load("scenes/fog-box.xml", res=8))


@pytest.fixture(scope="module", params=["caustic-closeup", "caustics-box"])
def caustic_runs(request):
    """As ``runs``, on a glass sphere's caustic (refraction chains, k = 2) and a mirror sphere's
    (reflection, k = 1): most photons under the sphere have a specular parent."""
    scene = load(f"scenes/{request.param}.xml", res=16)
    out = []
    for seed in range(N_SEEDS):
        f = render(make("gpm", scene, seed=700 + seed, **{**FIXED, "radius": 0.05}), spp=16)
        pb = f.images["primal_base"].mean(-1)
        fdx = np.zeros_like(pb)
        fdx[:, :-1] = pb[:, 1:] - pb[:, :-1]
        fdy = np.zeros_like(pb)
        fdy[:-1] = pb[1:] - pb[:-1]
        out.append(np.stack([f.gx.mean(-1) - fdx, f.gy.mean(-1) - fdy, f.gx.mean(-1), fdx]))
        last = f
    return request.param, np.array(out), last


def test_manifold_shifts_are_unbiased(caustic_runs):
    """The manifold branch (Eq. 7-8): photons under the spheres are moved by the walk -- through
    the glass sphere's two refractions (k = 2) and off the mirror (k = 1), counted -- and the
    gradients stay unbiased at a fixed radius (tolerances as in test_unbiased_at_fixed_radius), over
    the image and over the pixels where the walk does most. Setting the chain's Jacobian to 1
    fails it (mean z^2 2.4 on the mirror's caustic, 96 on the glass sphere's); Eq. 6 is 1 on these
    flat floors and is checked by the finite-difference test above. The per-pass replicate test of
    tests/test_gpm_manifold.py resolves a much smaller bias on the same two chains."""
    name, d, last = caustic_runs
    moved = last.images["shift_manifold"].sum()
    # caustics box: 4 % of the shifts at 16 x 16 with the mirror alone, more with the glass walked;
    # the close-up: every photon under the glass ball has a two-refraction parent chain
    assert moved > 0.02 * last.images["shift_reconnected"].sum(), name
    # the whole image, and the pixels where the walk does most (the caustics), on their own
    wheres = [np.ones(d.shape[2:], bool)]
    wheres.append(last.images["shift_manifold"] > 0.3 * last.images["shift_manifold"].max())
    for i in range(2):
        for where in wheres:
            z = _z(d[:, i][:, where])
            assert (z ** 2).mean() < 1.45, f"{name}: mean z^2 {(z ** 2).mean():.2f} (max |z| {np.abs(z).max():.1f})"
            assert np.abs(z).max() < 5.5, name


def test_specular_parent_subset_goes_to_the_manifold_branch_only():
    """Hua et al. 2017's Fig. 4 subset (parent="specular"): the base is SPPM's estimate of the same
    subset, and no photon of it is reconnected -- every shift is the manifold walk's or fails --
    while the complement never walks."""
    scene = load("scenes/caustics-box.xml", res=8)
    kw = dict(seed=4, photons_per_pass=20_000, radius=0.08, alpha=1.0)
    spec = render(make("gpm", scene, parent="specular", **kw), spp=2)
    assert np.array_equal(spec.images["primal_base"], render(make("sppm", scene, parent="specular", **kw), spp=2).primal)
    assert spec.stats["photon_shifts_reconnected"] == 0 and spec.stats["photon_shifts_manifold"] > 0
    rest = render(make("gpm", scene, parent="non-specular", **kw), spp=2)
    assert rest.stats["photon_shifts_manifold"] == 0 and rest.stats["photon_shifts_reconnected"] > 0


def test_mis_weights_of_a_pair_sum_to_one():
    """PHOTONS.md T2/T4 on real light paths of the Cornell box: a photon y_s moved to y* = y_s + D in
    its plane (the reconnection branch, y'_s = y*) and the reverse shift from y* back to y_s give
    density ratios r and r' with r r' = 1, so w(x) + w(T x) = 1 to 1e-9, and power ratios that
    invert; a shift that fails one way (the parent's hemisphere, an emitter's back) fails the other
    way too. Random displacements up to a tenth of the box; parents on the light and on walls."""
    from gdlearn.integrators.photon.gpm_light import parent_factor
    from gdlearn.photons.records import K_SURFACE
    from gdlearn.shifts.mis import mis_weight_from_log_ratio
    from gdlearn.shifts.photon import photon_geometry_ratio

    g = make("gpm", load("scenes/cornell-box.xml", res=8), photons_per_pass=100)
    sa = g.setup.sa
    lp = g.tracer.trace(7, 0, 0, 400)
    rng = np.random.default_rng(5)
    tested = {0: 0, 1: 0}
    for v in np.flatnonzero((lp.depth >= 1) & (lp.kind == K_SURFACE) & (lp.parent >= 0)):
        q = lp.parent[v]
        nv = lp.nrm[v]
        a = np.cross(nv, [0.3, 0.5, 0.7])
        a /= np.linalg.norm(a)
        b = np.cross(nv, a)
        ys = lp.pos[v].copy()
        ystar = ys + rng.uniform(-0.2, 0.2) * a + rng.uniform(-0.2, 0.2) * b
        fwd = _ratio_one_way(sa, lp, q, v, ys, nv, ystar, parent_factor, photon_geometry_ratio)
        lp2 = type(lp)(*(f.copy() for f in lp))
        lp2.pos[v] = ystar
        dv = ystar - lp.pos[q]
        lp2.d_in[v] = dv / np.linalg.norm(dv)
        rev = _ratio_one_way(sa, lp2, q, v, ystar, nv, ys, parent_factor, photon_geometry_ratio)
        assert fwd[0] == rev[0], (v, fwd, rev)
        if fwd[0] != 0:
            continue
        r, r2 = fwd[2], rev[2]
        w = mis_weight_from_log_ratio(math.log(r)) + mis_weight_from_log_ratio(math.log(r2))
        assert w == pytest.approx(1.0, abs=1e-9)
        assert np.allclose(np.array(fwd[1]) * np.array(rev[1]), 1.0, rtol=1e-9)
        tested[int(lp.kind[q] != 0)] += 1
    assert tested[0] > 20 and tested[1] > 20, tested      # parents on the light and on surfaces


def _ratio_one_way(sa, lp, q, v, ys, nv, ystar, parent_factor, photon_geometry_ratio):
    """(status, power ratio, density ratio) of moving photon v from ys to ystar (normal nv)."""
    yq = lp.pos[q]
    d = ystar - yq
    d /= np.linalg.norm(d)
    status, fr, pr = parent_factor(sa, lp, q, v, tuple(d))
    if status != 0:
        return status, fr, 0.0
    geo = photon_geometry_ratio(tuple(yq), tuple(ys), tuple(nv), tuple(ystar), tuple(nv))
    return status, tuple(f * geo for f in fr), pr * geo


def test_first_radius_is_a_fraction_of_sppms_footprint(cornell):
    """gpm starts from RADIUS_SCALE pixel footprints, SPPM from one (gpm's module docstring: the
    gradients afford a smaller kernel); an explicit radius_scale or radius still wins."""
    from gdlearn.integrators.photon.gpm import RADIUS_SCALE

    foot = make("sppm", cornell, photons_per_pass=100).initial_radius2()
    assert np.allclose(make("gpm", cornell, photons_per_pass=100).initial_radius2(), RADIUS_SCALE ** 2 * foot,
                       rtol=1e-12)
    assert np.allclose(make("gpm", cornell, photons_per_pass=100, radius_scale=1.0).initial_radius2(), foot,
                       rtol=1e-12)
    assert np.all(make("gpm", cornell, photons_per_pass=100, radius=0.05).initial_radius2() == 0.05 ** 2)
