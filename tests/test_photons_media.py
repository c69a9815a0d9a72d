"""Light paths through participating media and null interfaces (gdlearn.photons.trace).

Every expected value here is computed independently of the tracer -- closed forms, scipy quadrature,
a Fresnel formula written out below -- and compared within k standard errors of the Monte Carlo
estimate (k = 4 unless said otherwise: a false alarm ~6e-5 per check). Seeds are fixed, so a run is
reproducible; the tolerances are what make a correct tracer pass for *any* seed.

Planted bugs, each shown to fail this file (one at a time, in gdlearn/photons/trace.py; the
tests that failed in brackets):

* pass weight T / P(pass) replaced by 1                [slab transmittance, chromatic]
* albedo dropped from the collision weight              [first collision, ball density]
* 1 / dist^2 dropped from a medium vertex's pdf_fwd     [first collision]
* P(pass) dropped from a surface vertex's pdf_fwd       [slab transmittance, both]
* ``e = 1.0`` in ``_adjoint_weight`` (eta^2 kept)       [glass floor]
* a null vertex records the medium it leads into        [slab transmittance, records]
* every path starts in the outer medium (no locating)   [first collision, ball density, records]
* free flights sampled with 1.05 sigma_t                [first collision (KS), slab transmittance]
* light path keyed by its row in the batch, not j       [thread / batch independence, both scenes]
* roulette survivors not divided by q                   [albedo series with roulette]
* collision weight taken as the albedo (grey shortcut)  [chromatic collisions]
"""
import math
from pathlib import Path

import numba
import numpy as np
import pytest
from scipy import integrate, stats

import gdlearn.scene
from gdlearn.kernels import layout as L
from gdlearn.photons.records import F_DELTA_OUT, F_PHOTON, K_EMITTER, K_MEDIUM, K_SURFACE
from gdlearn.photons.trace import LightTracer, TraceParams
from gdlearn.scene.compile import compile_scene

ROOT = Path(__file__).resolve().parent.parent
SCENES = ROOT / "tests/scenes_photons"
K = 4.0                                   # standard errors allowed


def _sa(path, **defaults):
    return compile_scene(gdlearn.scene.load(str(path), **defaults))


def _trace(sa, n, *, seed=7, max_vertices=6, rr_depth=50, want_volume=True, threads=None, batch=16384):
    prm = TraceParams(max_vertices, rr_depth, 0.05, True, True, want_volume=want_volume)
    return LightTracer(sa, prm, batch=batch, threads=threads).trace(seed, 0, 0, n)


def _within(est, se, expected, k=K, slack=0.0):
    return abs(est - expected) <= k * se + slack


def _per_path(lp, rows, n, values):
    """Per-light-path sums of ``values`` (one row per entry of ``rows``) over all n emitted paths."""
    out = np.zeros((n,) + values.shape[1:])
    np.add.at(out, lp.path[rows], values)
    return out


# -- 1. first collisions around a point light ----------------------------------------------------
SIG, ALB, I_PT = 1.5, 0.7, 2.0


@pytest.fixture(scope="module")
def point_medium():
    sa = _sa(SCENES / "medium-point.xml", sigma_t=f"{SIG}, {SIG}, {SIG}", albedo=ALB, I=I_PT, g=0.0)
    return sa, _trace(sa, 60000, max_vertices=2)


def test_first_collision_distance_is_exponential_and_weight_is_power_times_albedo(point_medium):
    sa, lp = point_medium
    first = np.flatnonzero(lp.depth == 1)
    # sigma_t R = 60: every path collides before the boundary, and its first vertex is in the medium
    assert first.size == 60000 and (lp.kind[first] == K_MEDIUM).all()
    r = np.linalg.norm(lp.pos[first], axis=1)
    # KS against sigma_t exp(-sigma_t r); p > 1e-3 (a 2% error in sigma_t has p ~ 1e-8 at this n)
    assert stats.kstest(r, "expon", args=(0.0, 1.0 / SIG)).pvalue > 1e-3
    # the weight of a first collision is Phi sigma_s / sigma_t with Phi = 4 pi I; grey medium: every
    # weight is that exact number, so the mean matches to rounding (and within K SE trivially)
    w = lp.beta[first].mean(axis=1)
    phi = 4.0 * math.pi * I_PT
    assert _within(w.mean(), w.std() / math.sqrt(w.size), phi * ALB, slack=1e-12 * phi)
    # volume-measure pdf given the point light: (1 / 4 pi) sigma_t exp(-sigma_t r) / r^2 (PHOTONS.md E2)
    np.testing.assert_allclose(lp.pdf_fwd[first], SIG * np.exp(-SIG * r) / (4 * math.pi * r * r), rtol=1e-9)
    # reverse pdf of the light from the first vertex (isotropic phase): (1/4 pi) P(pass r) / r^2
    second = np.flatnonzero(lp.depth == 2)
    v1 = lp.parent[second]
    r1 = np.linalg.norm(lp.pos[v1], axis=1)
    assert second.size > 10000 and (lp.depth[v1] == 1).all()
    np.testing.assert_allclose(lp.pdf_rev[lp.parent[v1]], np.exp(-SIG * r1) / (4 * math.pi * r1 ** 2), rtol=1e-9)


def _ball_integral(f, dist, rho):
    """int over the ball (centre at distance dist from the origin, radius rho) of f(|x|) dV, as
    int f(r) A(r) dr with A(r) the area of the sphere of radius r inside the ball."""
    def area(r):
        c = (r * r + dist * dist - rho * rho) / (2 * r * dist)
        return 2 * math.pi * r * r * (1 - min(1.0, max(-1.0, c)))
    val, err = integrate.quad(lambda r: f(r) * area(r), dist - rho, dist + rho, epsabs=0, epsrel=1e-10)
    return val


def test_collision_density_in_a_ball_matches_the_uncollided_fluence(point_medium):
    """Sum of first-collision photon weights in a ball / (V N) estimates sigma_s phi_0, with the
    uncollided fluence phi_0(r) = Phi exp(-sigma_t r) / (4 pi r^2) (Jarosz et al. 2008, Eq. 4 read as
    a density of sigma_s-weighted flux); its ball average is integrated with scipy."""
    sa, lp = point_medium
    n = 60000
    c, rho = np.array([0.48, 0.0, 0.64]), 0.3        # |c| = 0.8
    first = np.flatnonzero(lp.depth == 1)
    inside = first[np.linalg.norm(lp.pos[first] - c, axis=1) < rho]
    vol = 4.0 / 3.0 * math.pi * rho ** 3
    x = _per_path(lp, inside, n, lp.beta[inside].mean(axis=1)) / vol
    phi = 4.0 * math.pi * I_PT
    expected = _ball_integral(lambda r: ALB * SIG * phi * math.exp(-SIG * r) / (4 * math.pi * r * r), 0.8, rho) / vol
    assert inside.size > 300
    assert _within(x.mean(), x.std() / math.sqrt(n), expected)


def test_chromatic_collision_weights_use_the_spectral_mis_density():
    """RGB sigma_t (1, 1.5, 2.5): one collision serves all channels, its weight sigma_s,c T_c / pdf
    with the spectral-MIS pdf (1/3) sum_c sigma_c T_c. Per channel the first collisions carry Phi a
    in total and, in the ball, sigma_s,c phi_0,c (as the grey test above, channel by channel)."""
    n, sig = 60000, (1.0, 1.5, 2.5)
    sa = _sa(SCENES / "medium-point.xml", sigma_t=", ".join(map(str, sig)), albedo=ALB, I=I_PT, g=0.0)
    lp = _trace(sa, n, max_vertices=1)
    first = np.flatnonzero(lp.depth == 1)
    phi = 4.0 * math.pi * I_PT
    x = _per_path(lp, first, n, lp.beta[first])
    c, rho = np.array([0.48, 0.0, 0.64]), 0.3
    inside = first[np.linalg.norm(lp.pos[first] - c, axis=1) < rho]
    vol = 4.0 / 3.0 * math.pi * rho ** 3
    y = _per_path(lp, inside, n, lp.beta[inside]) / vol
    for ch in range(3):
        assert _within(x[:, ch].mean(), x[:, ch].std() / math.sqrt(n), phi * ALB), ch
        s = sig[ch]
        expected = _ball_integral(lambda r: ALB * s * phi * math.exp(-s * r) / (4 * math.pi * r * r), 0.8, rho) / vol
        assert _within(y[:, ch].mean(), y[:, ch].std() / math.sqrt(n), expected), (ch, y[:, ch].mean(), expected)
    # the volume pdf of a first collision is the MIS density (1/3) sum_c sigma_c exp(-sigma_c r) / (4 pi r^2)
    r = np.linalg.norm(lp.pos[first], axis=1)
    mis = np.mean([s * np.exp(-s * r) for s in sig], axis=0)
    np.testing.assert_allclose(lp.pdf_fwd[first], mis / (4 * math.pi * r * r), rtol=1e-9)


@pytest.mark.parametrize("max_vertices, rr_depth", [(64, 1), (3, 50)])
def test_scattered_power_sums_to_the_albedo_series(max_vertices, rr_depth):
    """Energy balance in an unbounded grey medium (sigma_t R = 60: no path reaches the boundary): the
    k-th collision carries Phi a^k on average, whatever the phase function (here HG g = 0.6), so the
    weights of all medium vertices of a path sum to Phi sum_{k <= K} a^k on average -- with Russian
    roulette from the first vertex on (which must divide by its survival probability) and with the
    series cut at max_vertices K = 3 and no roulette."""
    n = 40000
    sa = _sa(SCENES / "medium-point.xml", sigma_t=f"{SIG}, {SIG}, {SIG}", albedo=ALB, I=I_PT, g=0.6)
    lp = _trace(sa, n, max_vertices=max_vertices, rr_depth=rr_depth)
    med = np.flatnonzero(lp.kind == K_MEDIUM)
    assert (lp.kind[lp.depth > 0] == K_MEDIUM).all()
    x = _per_path(lp, med, n, lp.beta[med].mean(axis=1))
    phi = 4.0 * math.pi * I_PT
    expected = phi * sum(ALB ** k for k in range(1, max_vertices + 1))
    # without roulette every path's sum is that exact number; with it the spread is the roulette's
    assert _within(x.mean(), x.std() / math.sqrt(n), expected, slack=1e-9 * expected)


# -- 2. transmittance through a slab behind null interfaces -------------------------------------
HALF, CUT, I_SPOT = 0.25, 12.0, 5.0


def _unscattered_on_floor(sa, lp):
    """Rows of the floor's first-bounce vertices (depth 1: nothing scattered before them)."""
    floor = [i for i, m in enumerate(sa.materials) if int(m[L.MAT_TYPE]) == L.DIFFUSE][0]
    return np.flatnonzero((lp.kind == K_SURFACE) & (lp.obj == floor) & (lp.depth == 1))


def _cone_integral(f):
    """I int_cone f(cos) d omega for the uniform spot of the slab scene."""
    cc = math.cos(math.radians(CUT))
    val, _ = integrate.quad(f, cc, 1.0, epsabs=0, epsrel=1e-11)
    return I_SPOT * 2 * math.pi * val


@pytest.mark.parametrize("sigma", [(1.0, 2.0, 4.0), (0.3, 0.3, 0.3)])
def test_unscattered_power_through_a_null_bounded_slab_is_the_transmittance(sigma):
    n = 40000
    sa0 = _sa(SCENES / "slab-medium.xml", sigma_t="0, 0, 0", half=HALF, cutoff=CUT, I=I_SPOT)
    lp0 = _trace(sa0, n)
    rows0 = _unscattered_on_floor(sa0, lp0)
    # no medium: every photon of the cone reaches the floor through both null faces, weight unchanged
    clear = lp0.beta[rows0].sum(axis=0) / n
    np.testing.assert_allclose(clear, _cone_integral(lambda mu: 1.0), rtol=1e-9)

    sa = _sa(SCENES / "slab-medium.xml", sigma_t=", ".join(map(str, sigma)), half=HALF, cutoff=CUT, I=I_SPOT)
    lp = _trace(sa, n)
    rows = _unscattered_on_floor(sa, lp)
    x = _per_path(lp, rows, n, lp.beta[rows])
    for ch in range(3):
        expected = _cone_integral(lambda mu: math.exp(-sigma[ch] * 2 * HALF / mu))
        assert _within(x[:, ch].mean(), x[:, ch].std() / math.sqrt(n), expected), (ch, x[:, ch].mean(), expected)
    # the chain emitter -> null (top, vacuum edge) -> null (bottom, medium edge) -> floor (vacuum edge)
    b, a = lp.parent[rows], lp.parent[lp.parent[rows]]
    assert (lp.kind[lp.parent[a]] == K_EMITTER).all()
    for q in (a, b):
        assert (lp.lobe[q] == -1).all() and (lp.flags[q] & F_DELTA_OUT).all() and not (lp.flags[q] & F_PHOTON).any()
    assert (lp.medium[a] == -1).all() and (lp.medium[b] == 0).all() and (lp.medium[rows] == -1).all()
    # pdfs: top face from the spot, pass probability (1/3) sum_c exp(-sigma_c t) across the slab
    # times |cos| / t^2 at the bottom face, |cos| / t^2 at the floor (a null vertex samples nothing: 1)
    cc = math.cos(math.radians(CUT))
    d = lp.d_in[rows]
    t_top = np.linalg.norm(lp.pos[a] - lp.pos[lp.parent[a]], axis=1)
    t_slab = np.linalg.norm(lp.pos[b] - lp.pos[a], axis=1)
    t_floor = np.linalg.norm(lp.pos[rows] - lp.pos[b], axis=1)
    cz = np.abs(d[:, 2])
    np.testing.assert_allclose(lp.pdf_fwd[a], cz / t_top ** 2 / (2 * math.pi * (1 - cc)), rtol=1e-6)
    pp = np.mean([np.exp(-s * t_slab) for s in sigma], axis=0)
    np.testing.assert_allclose(lp.pdf_fwd[b], pp * cz / t_slab ** 2, rtol=1e-6)
    np.testing.assert_allclose(lp.pdf_fwd[rows], cz / t_floor ** 2, rtol=1e-6)


@pytest.mark.parametrize("sigma", [4e-6, 40.0])       # sigma_t L = 2e-6 (thin), 20 (dense)
def test_thin_and_dense_slabs_stay_finite(sigma):
    n = 20000
    sa = _sa(SCENES / "slab-medium.xml", sigma_t=f"{sigma}, {sigma}, {sigma}", half=HALF, cutoff=CUT, I=I_SPOT)
    lp = _trace(sa, n)
    child = lp.depth > 0
    assert np.isfinite(lp.beta).all() and np.isfinite(lp.pdf_fwd).all() and np.isfinite(lp.pdf_rev).all()
    assert (lp.pdf_fwd[lp.parent >= 0] > 0).all() and (lp.pdf_rev >= 0).all()
    med = lp.kind == K_MEDIUM
    assert (np.abs(lp.pos[med, 2]) <= HALF + 1e-9).all()
    rows = _unscattered_on_floor(sa, lp)
    x = _per_path(lp, rows, n, lp.beta[rows].mean(axis=1))
    expected = _cone_integral(lambda mu: math.exp(-sigma * 2 * HALF / mu))
    # grey medium: a photon reaches the floor unscattered with weight I Omega and probability
    # T = expected / (I Omega), so the binomial standard error I Omega sqrt(T (1 - T) / n) is the
    # exact one (the sample's is 0 when no photon, or every photon, gets through: dense / thin)
    full = _cone_integral(lambda mu: 1.0)
    tr = expected / full
    se = full * math.sqrt(tr * (1 - tr) / n)
    assert _within(x.mean(), se, expected, slack=1e-12 * full)
    assert child.any()


# -- 3. refraction: importance carries no eta^2 ---------------------------------------------------
def _fresnel(mu, eta):
    """Unpolarised Fresnel reflectance from outside (index 1) into index eta at incidence cosine mu."""
    s2 = (1 - mu * mu) / (eta * eta)
    mt = math.sqrt(1 - s2)
    rs = (mu - eta * mt) / (mu + eta * mt)
    rp = (eta * mu - mt) / (eta * mu + mt)
    return 0.5 * (rs * rs + rp * rp)


def test_power_reaching_a_floor_under_glass_is_the_fresnel_transmitted_power():
    """Every photon on the floor inside the block crossed the top face once, by refraction: its
    power is I int (1 - F) d omega. Radiance's eta^2 = 2.25 scaling kept (``e = 1.0`` planted in
    _adjoint_weight) scales it by 1/2.25 and fails by hundreds of standard errors."""
    n, cut, eta, inten = 40000, 40.0, 1.5, 5.0
    sa = _sa(SCENES / "glass-floor.xml", cutoff=cut, eta=eta, I=inten)
    lp = _trace(sa, n, want_volume=False)
    floor = [i for i, m in enumerate(sa.materials) if int(m[L.MAT_TYPE]) == L.DIFFUSE][0]
    rows = np.flatnonzero((lp.kind == K_SURFACE) & (lp.obj == floor) & (lp.depth == 2))
    assert (lp.lobe[lp.parent[rows]] == L.V_SPECULAR).all()
    x = _per_path(lp, rows, n, lp.beta[rows].mean(axis=1))
    cc = math.cos(math.radians(cut))
    expected = inten * 2 * math.pi * integrate.quad(lambda mu: 1 - _fresnel(mu, eta), cc, 1.0, epsrel=1e-11)[0]
    assert _within(x.mean(), x.std() / math.sqrt(n), expected), (x.mean(), expected)


# -- 4. determinism and records ------------------------------------------------------------------
@pytest.mark.parametrize("scene", ["scenes/spot-medium.xml", "scenes/test/medium-room.xml"])
def test_same_records_for_one_and_two_threads_in_media(scene):
    sa = _sa(ROOT / scene, res=8)
    a = _trace(sa, 3000, threads=1, batch=1024, rr_depth=3)
    b = _trace(sa, 3000, threads=min(2, numba.config.NUMBA_NUM_THREADS), batch=4096, rr_depth=3)
    for name, x, y in zip(a._fields, a, b):
        assert np.array_equal(x, y), name
    assert (a.kind == K_MEDIUM).any() and ((a.kind == K_SURFACE) & (a.lobe < 0) & (a.depth > 0)).any()


@pytest.fixture(scope="module")
def room():
    sa = _sa(ROOT / "scenes/test/medium-room.xml", res=8)
    return sa, _trace(sa, 20000, rr_depth=3)


def test_medium_records_kinds_links_and_edges(room):
    sa, lp = room
    root = lp.depth == 0
    rows = np.arange(len(lp))
    assert (lp.kind[root] == K_EMITTER).all() and (lp.parent[root] == -1).all()
    child = lp.parent >= 0
    assert np.array_equal(child, lp.kind != K_EMITTER)
    assert np.array_equal(lp.parent[child], rows[child] - 1) and (lp.path[child] == lp.path[lp.parent[child]]).all()
    # medium vertices: obj = their medium = the medium of the edge that arrived, no primitive, no normal
    med = lp.kind == K_MEDIUM
    assert med.sum() > 1000
    assert (lp.obj[med] == lp.medium[med]).all() and (lp.medium[med] == 0).all() and (lp.prim[med] == -1).all()
    assert (lp.nrm[med] == 0).all() and (lp.flags[med] & F_PHOTON).all()
    assert np.isin(lp.lobe[med], (L.V_MEDIUM, -1)).all()
    # null vertices: the null material, no lobe, a kept direction, never photons
    null = (lp.kind == K_SURFACE) & (sa.materials[np.maximum(lp.obj, 0), L.MAT_TYPE] == L.NULL)
    assert null.sum() > 1000
    assert (lp.lobe[null] == -1).all() and (lp.flags[null] & F_DELTA_OUT).all() and not (lp.flags[null] & F_PHOTON).any()
    after = np.flatnonzero(null)[np.flatnonzero(null) + 1 < len(lp)] + 1
    after = after[lp.parent[after] == after - 1]
    np.testing.assert_allclose(lp.d_in[after], lp.d_in[after - 1], atol=1e-12)
    # depth counts scattering vertices: +1 past a scattering parent, a null's own depth past a null
    sc = child & ~null
    par = lp.parent[sc]
    assert np.array_equal(lp.depth[sc], np.where(null[par], lp.depth[par], lp.depth[par] + 1))
    # every edge lies in one medium: haze inside the cube (half-size 1.5), vacuum outside
    e = lp.pos[child] - lp.pos[lp.parent[child]]
    mid = 0.5 * (lp.pos[child] + lp.pos[lp.parent[child]])
    in_cube = (np.abs(mid) < 1.5).all(axis=1)
    assert np.array_equal(in_cube, lp.medium[child] == 0)
    # d_in runs from parent to child: the child lies on the parent's ray up to the ~1e-7 push-off of
    # ray origins at null crossings (a relative test would fail on edges of length ~1e-4)
    assert (np.einsum("ij,ij->i", e, lp.d_in[child]) > 0).all()
    assert (np.linalg.norm(np.cross(e, lp.d_in[child]), axis=1) < 1e-6).all()
    # pdfs finite and positive
    assert (lp.pdf_fwd[child] > 0).all() and np.isfinite(lp.pdf_fwd).all() and np.isfinite(lp.beta).all()
    assert (lp.pdf_rev >= 0).all() and np.isfinite(lp.pdf_rev).all()
    # start media: the light inside the cube starts in haze, the point and the outer area light in vacuum
    inside = (np.abs(lp.pos[root]) < 1.5).all(axis=1)
    assert np.array_equal(lp.medium[root], np.where(inside, 0, -1))


def test_volume_photons_only_when_asked_and_global_media(room, tmp_path):
    sa, _ = room
    lp = _trace(sa, 3000, rr_depth=3, want_volume=False)
    med = lp.kind == K_MEDIUM
    assert med.any() and not (lp.flags[med] & F_PHOTON).any()
    # fog-box: every surface names fog on both sides, the light starts in it
    fog = _sa(ROOT / "scenes/fog-box.xml", res=8)
    lp = _trace(fog, 2000, rr_depth=3)
    assert (lp.medium == 0).all() and (lp.kind == K_MEDIUM).any()
    # a global medium: only the sensor names it, no shape is a medium transition
    text = (SCENES / "plane-point.xml").read_text()
    text = text.replace("<sensor type=\"perspective\">", "<medium type=\"homogeneous\" id=\"air\"><float "
                        "name=\"sigma_t\" value=\"0.5\"/></medium>\n    <sensor type=\"perspective\"><ref id=\"air\"/>")
    p = tmp_path / "plane-point-air.xml"
    p.write_text(text)
    air = _sa(p)
    lp = _trace(air, 2000, rr_depth=3)
    assert (lp.medium == 0).all() and (lp.kind == K_MEDIUM).any()
