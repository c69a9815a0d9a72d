"""BSDF kernels (gdlearn.kernels.bsdf.dispatch): chi^2 goodness of fit of every sampler against its own pdf
integrated numerically, sample/eval/pdf consistency, normalisation, white-furnace energy bounds,
delta lobes against textbook Fresnel / Snell, vertex classes and numerical stability."""
import math
import zlib

import numpy as np
import pytest
from numba import njit

from gdlearn.kernels.bsdf import dispatch as B
from gdlearn.kernels import layout as L
from gdlearn.kernels.bsdf.plastic import ROUGHPLASTIC_WIDTH
from gdlearn.scene.model import BSDF, rgb
from test_kernels_helpers import chi2_pvalue, sphere_bins, sphere_grid

N = 100_000
ALPHA = 1e-3
N_COS, N_PHI, K = 20, 40, 10      # bins over (cos theta, phi); K x K Gauss-Legendre points per bin


_ROWS = {}


def row_of(**kw):
    """Material row for BSDF(**kw), cached: a roughplastic's table takes ~1 s to integrate."""
    key = repr(sorted((k, np.asarray(v).tolist() if isinstance(v, np.ndarray) else v) for k, v in kw.items()))
    if key not in _ROWS:
        _ROWS[key] = B.material_row(BSDF(**kw), width=ROUGHPLASTIC_WIDTH)
    return _ROWS[key]


def wi_at(cos_t, phi=0.3):
    s = math.sqrt(max(0.0, 1 - cos_t * cos_t))
    return (s * math.cos(phi), s * math.sin(phi), cos_t)


@njit(cache=True)
def _sample_many(row, wi, u):
    n = u.shape[0]
    wo = np.zeros((n, 3))
    w = np.zeros((n, 3))
    pdf = np.zeros(n)
    delta = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        d, ww, p, dl = B.bsdf_sample(row, wi, u[i, 0], u[i, 1], u[i, 2])
        wo[i, 0], wo[i, 1], wo[i, 2] = d
        w[i, 0], w[i, 1], w[i, 2] = ww
        pdf[i] = p
        delta[i] = dl
    return wo, w, pdf, delta


@njit(cache=True)
def _eval_pdf_many(row, wi, dirs, pair=False):
    """f |cos wo| and pdf at each direction: by bsdf_eval and bsdf_pdf, or with ``pair`` by
    bsdf_eval_pdf."""
    n = dirs.shape[0]
    f = np.zeros((n, 3))
    pdf = np.zeros(n)
    for i in range(n):
        wo = (dirs[i, 0], dirs[i, 1], dirs[i, 2])
        if pair:
            ff, pdf[i] = B.bsdf_eval_pdf(row, wi, wo)
        else:
            ff, pdf[i] = B.bsdf_eval(row, wi, wo), B.bsdf_pdf(row, wi, wo)
        f[i, 0], f[i, 1], f[i, 2] = ff
    return f, pdf


def _samples(row, wi, seed, n=N):
    u = np.random.default_rng(seed).random((n, 3))
    return _sample_many(row, wi, u)


# (name, material kwargs, cos theta_i); rough lobes at two roughnesses, several incidences, both sides
CHI2_CASES = [
    ("diffuse", dict(type="diffuse"), 0.5),
    ("diffuse-twosided-back", dict(type="diffuse", twosided=True), -0.4),
    ("plastic", dict(type="plastic", reflectance=rgb(0.3, 0.5, 0.7), int_ior=1.49, ext_ior=1.000277), 0.6),
    ("plastic-grazing", dict(type="plastic", int_ior=1.49, ext_ior=1.0), 0.1),
]
for dist in ("beckmann", "ggx"):
    for alpha in (0.15, 0.5):
        for ci in (0.9, 0.3):
            CHI2_CASES.append((f"roughconductor-{dist}-{alpha}-{ci}",
                               dict(type="roughconductor", distribution=dist, alpha=alpha,
                                    reflectance=rgb(1.0)), ci))
        for ci in (0.7, -0.5, 0.15):
            CHI2_CASES.append((f"roughdielectric-{dist}-{alpha}-{ci}",
                               dict(type="roughdielectric", distribution=dist, alpha=alpha,
                                    int_ior=1.5, ext_ior=1.0), ci))
    CHI2_CASES.append((f"roughplastic-{dist}", dict(type="roughplastic", distribution=dist, alpha=0.3,
                                                    reflectance=rgb(0.4), int_ior=1.5, ext_ior=1.0), 0.5))
    CHI2_CASES.append((f"roughconductor-twosided-{dist}",
                       dict(type="roughconductor", distribution=dist, alpha=0.3, twosided=True), -0.6))


@pytest.mark.parametrize("name,kw,ci", CHI2_CASES, ids=[c[0] for c in CHI2_CASES])
def test_sampling_chi2_and_consistency(name, kw, ci):
    row = row_of(**kw)
    wi = wi_at(ci)
    wo, w, pdf, delta = _samples(row, wi, seed=zlib.crc32(name.encode()))
    cont = (pdf > 0) & ~delta
    # expected counts: the sampler's own pdf (bsdf_pdf) integrated over every bin
    q, qw = sphere_grid(N_COS, N_PHI, K)
    _, qpdf = _eval_pdf_many(row, wi, q)
    mass = (qpdf * qw).reshape(N_COS, N_PHI, -1).sum(-1)
    total = mass.sum()
    assert total <= 1.0 + 2e-3, total         # a pdf never integrates above 1 (2e-3: quadrature)
    obs = sphere_bins(wo[cont], N_COS, N_PHI).ravel()
    exp = mass.ravel() * N
    # one extra bin: delta-lobe and invalid samples, expected N (1 - integral of the pdf)
    obs = np.append(obs, np.count_nonzero(~cont))
    exp = np.append(exp, max(N * (1.0 - total), 0.0))
    assert chi2_pvalue(obs, exp) > ALPHA
    # every non-delta sample: pdf == bsdf_pdf(wi, wo) and weight == bsdf_eval / pdf
    f, p2 = _eval_pdf_many(row, wi, wo[cont])
    np.testing.assert_allclose(pdf[cont], p2, rtol=1e-9)
    np.testing.assert_allclose(w[cont], f / p2[:, None], rtol=1e-9, atol=1e-14)
    assert np.all(np.isfinite(w)) and np.all(np.isfinite(pdf))


@pytest.mark.parametrize("name,kw,ci", CHI2_CASES, ids=[c[0] for c in CHI2_CASES])
def test_eval_pdf_is_eval_and_pdf_bit_for_bit(name, kw, ci):
    """``bsdf_eval_pdf`` (one call where a next-event estimate or a sample needs both; the rough
    plastic shares its half vector, D, G1 and transmittance) returns exactly ``bsdf_eval`` and
    ``bsdf_pdf``: at directions all over the sphere and at sampled ones. Computing the pair's pdf
    with G1(wo) in place of G1(wi) fails the rough plastic's cases."""
    row, wi = row_of(**kw), wi_at(ci)
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    d = rng.normal(size=(3000, 3))
    dirs = np.vstack([d / np.linalg.norm(d, axis=1)[:, None], _samples(row, wi, 1, n=3000)[0]])
    f, pdf = _eval_pdf_many(row, wi, dirs)
    f2, pdf2 = _eval_pdf_many(row, wi, dirs, True)
    assert np.any(pdf > 0) and np.array_equal(f, f2) and np.array_equal(pdf, pdf2)


def test_chi2_detects_a_wrong_pdf():
    """Sampling GGX alpha=0.3 but expecting alpha=0.35 must fail (the test has power)."""
    wi = wi_at(0.7)
    wo, w, pdf, delta = _samples(row_of(type="roughconductor", distribution="ggx", alpha=0.3), wi, 3)
    q, qw = sphere_grid(N_COS, N_PHI, K)
    _, qpdf = _eval_pdf_many(row_of(type="roughconductor", distribution="ggx", alpha=0.35), wi, q)
    mass = (qpdf * qw).reshape(N_COS, N_PHI, -1).sum(-1)
    cont = pdf > 0
    obs = np.append(sphere_bins(wo[cont], N_COS, N_PHI).ravel(), np.count_nonzero(~cont))
    exp = np.append(mass.ravel() * N, N * max(0.0, 1 - mass.sum()))
    assert chi2_pvalue(obs, exp) < 1e-6


def test_diffuse_pdf_integrates_to_one_and_matches_lambert():
    row = row_of(type="diffuse", reflectance=rgb(0.2, 0.4, 0.6))
    q, qw = sphere_grid(N_COS, N_PHI, K)
    f, pdf = _eval_pdf_many(row, wi_at(0.3), q)
    assert (pdf * qw).sum() == pytest.approx(1.0, abs=1e-6)
    up = q[:, 2] > 0
    np.testing.assert_allclose(f[up], np.outer(q[up, 2] / np.pi, [0.2, 0.4, 0.6]), rtol=1e-12)
    assert np.all(f[~up] == 0) and np.all(pdf[~up] == 0)


FURNACE = [
    ("diffuse", dict(type="diffuse", reflectance=rgb(1.0)), 1.0, 1e-12),
    ("conductor", dict(type="conductor", reflectance=rgb(1.0)), 1.0, 1e-12),
    ("roughconductor-ggx", dict(type="roughconductor", distribution="ggx", alpha=0.5, reflectance=rgb(1.0)), None, 0),
    ("roughconductor-beckmann", dict(type="roughconductor", alpha=0.5, reflectance=rgb(1.0)), None, 0),
    ("dielectric", dict(type="dielectric", int_ior=1.5, ext_ior=1.0), 1.0, 1e-12),
    ("roughdielectric", dict(type="roughdielectric", distribution="ggx", alpha=0.4, int_ior=1.5, ext_ior=1.0), None, 0),
    ("plastic", dict(type="plastic", reflectance=rgb(1.0), int_ior=1.5, ext_ior=1.0), None, 0),
    ("roughplastic", dict(type="roughplastic", alpha=0.3, reflectance=rgb(1.0), int_ior=1.5, ext_ior=1.0), None, 0),
]


@pytest.mark.parametrize("name,kw,exact,tol", FURNACE, ids=[f[0] for f in FURNACE])
@pytest.mark.parametrize("ci", [0.9, 0.4, -0.6])
def test_white_furnace(name, kw, exact, tol, ci):
    """Albedo = E[weight] (delta lobes included) must be <= 1 for white materials; lossless smooth
    lobes give exactly 1. Refraction weights are multiplied by eta^2 to undo the radiance scaling
    (energy, not radiance, is conserved). Tolerance: 4 standard errors, +1e-3 for plastics, whose
    Fresnel-fit internal reflectance (Mitsuba's F_dr fits, ~0.1% error) is not exactly reciprocal."""
    row = row_of(**kw)
    wi = wi_at(ci)
    wo, w, pdf, delta = _samples(row, wi, 11, n=200_000)
    # eta_it for refracted samples: wi.z * wo.z < 0 -> eta (from outside) or 1/eta (from inside)
    e = row[L.MAT_ETA]
    refr = wi[2] * wo[:, 2] < 0
    scale = np.where(refr, (e if wi[2] > 0 else 1 / e) ** 2, 1.0)
    a = (w * scale[:, None]).mean(0)
    se = (w * scale[:, None]).std(0) / math.sqrt(len(w))
    slack = 1e-3 if "plastic" in name else 0.0
    one_sided = not kw.get("twosided") and kw["type"] not in ("dielectric", "roughdielectric")
    if ci < 0 and one_sided:
        assert np.all(a == 0)
        return
    assert np.all(a <= 1 + 4 * se + slack), a
    if exact is not None:
        np.testing.assert_allclose(a, exact, atol=tol)
    else:
        assert np.all(a > 0.3)        # not trivially zero


def fresnel_textbook(cos_i, n1, n2):
    """Unpolarised Fresnel reflectance, Born & Wolf (Hecht, Optics, Eq. 4.34 / 4.40)."""
    s_i = math.sqrt(1 - cos_i**2)
    s_t = n1 / n2 * s_i
    if s_t >= 1:
        return 1.0
    c_t = math.sqrt(1 - s_t**2)
    rs = (n1 * cos_i - n2 * c_t) / (n1 * cos_i + n2 * c_t)
    rp = (n2 * cos_i - n1 * c_t) / (n2 * cos_i + n1 * c_t)
    return 0.5 * (rs * rs + rp * rp)


@pytest.mark.parametrize("ci", [0.95, 0.5, 0.1, -0.9, -0.5])
def test_smooth_dielectric_lobes(ci):
    """Reflection frequency = Fresnel F (binomial, 4 SE); refraction obeys Snell's law; weights are
    SR and ST * (eta_i / eta_t)^2 (radiance transport)."""
    eta = 1.5
    row = row_of(type="dielectric", int_ior=eta, ext_ior=1.0, specular_reflectance=rgb(0.9, 0.8, 0.7),
                 specular_transmittance=rgb(0.6, 0.5, 0.4))
    wi = wi_at(ci)
    n1, n2 = (1.0, eta) if ci > 0 else (eta, 1.0)
    F = fresnel_textbook(abs(ci), n1, n2)
    wo, w, pdf, delta = _samples(row, wi, 5, n=50_000)
    assert delta.all()
    refl = wo[:, 2] * ci > 0
    frac = refl.mean()
    assert abs(frac - F) <= 4 * math.sqrt(F * (1 - F) / len(wo)) + 1e-12
    if refl.any():
        np.testing.assert_allclose(wo[refl], np.tile([-wi[0], -wi[1], wi[2]], (refl.sum(), 1)), atol=1e-15)
        np.testing.assert_allclose(w[refl], np.tile([0.9, 0.8, 0.7], (refl.sum(), 1)))
        np.testing.assert_allclose(pdf[refl], F, rtol=1e-12)
    t = ~refl
    if t.any():
        sin_i = math.sqrt(1 - ci * ci)
        sin_t = np.hypot(wo[t, 0], wo[t, 1])
        np.testing.assert_allclose(n2 * sin_t, n1 * sin_i, rtol=1e-12)
        np.testing.assert_allclose(np.linalg.norm(wo[t], axis=1), 1.0, rtol=1e-12)
        np.testing.assert_allclose(w[t], np.tile(np.array([0.6, 0.5, 0.4]) * (n1 / n2) ** 2, (t.sum(), 1)))
        assert B.bsdf_eta(row, wi, tuple(wo[t][0])) == pytest.approx(n2 / n1)


def test_mirror_and_null():
    row = row_of(type="conductor", reflectance=rgb(0.9, 0.5, 0.1))
    wo, w, pdf, delta = B.bsdf_sample(row, (0.6, 0.0, 0.8), 0.3, 0.2, 0.1)
    assert wo == (-0.6, -0.0, 0.8) and w == (0.9, 0.5, 0.1) and pdf == 1.0 and delta
    assert B.bsdf_sample(row, (0.6, 0.0, -0.8), 0.3, 0.2, 0.1)[2] == 0.0       # one-sided
    assert B.bsdf_eval(row, (0, 0, 1.0), (0, 0, 1.0)) == (0.0, 0.0, 0.0)
    assert B.bsdf_is_delta_only(row) and B.bsdf_has_delta(row) and not B.bsdf_is_null(row)
    null = row_of(type="null")
    assert B.bsdf_is_null(null)
    assert B.bsdf_sample(null, (0.6, 0.0, 0.8), 0.5, 0.5, 0.5)[0] == (-0.6, -0.0, -0.8)


def test_vertex_classes():
    th = L.ROUGHNESS_THRESHOLD
    assert B.vertex_class(row_of(type="diffuse"), th) == L.V_DIFFUSE
    assert B.vertex_class(row_of(type="conductor"), th) == L.V_SPECULAR
    assert B.vertex_class(row_of(type="dielectric"), th) == L.V_SPECULAR
    assert B.vertex_class(row_of(type="roughconductor", alpha=0.3), th) == L.V_GLOSSY
    assert B.vertex_class(row_of(type="roughconductor", alpha=0.01), th) == L.V_SPECULAR
    assert B.vertex_class(row_of(type="roughdielectric", alpha=0.01), 0.005) == L.V_GLOSSY
    assert B.vertex_class(row_of(type="plastic"), th) == L.V_DIFFUSE
    assert B.lobe_class(row_of(type="plastic"), True, th) == L.V_SPECULAR
    assert B.lobe_class(row_of(type="plastic"), False, th) == L.V_DIFFUSE
    assert B.vertex_class(row_of(type="roughplastic"), th) == L.V_DIFFUSE
    assert not B.bsdf_has_delta(row_of(type="roughplastic"))
    assert B.bsdf_has_delta(row_of(type="plastic")) and not B.bsdf_is_delta_only(row_of(type="plastic"))


def test_material_row_errors_and_width():
    with pytest.raises(ValueError, match="MAT_WIDTH"):
        B.material_row(BSDF(type="roughplastic"), width=L.MAT_WIDTH)
    with pytest.raises(ValueError, match="unknown BSDF"):
        B.material_row(BSDF(type="velvet"))
    with pytest.raises(ValueError, match="int_ior"):
        B.material_row(BSDF(type="dielectric", int_ior=-1.0))
    for t in ("roughdielectric", "roughplastic"):     # Mitsuba 3 refuses these too
        with pytest.raises(ValueError, match="int_ior != ext_ior"):
            B.material_row(BSDF(type=t, int_ior=1.2, ext_ior=1.2), width=ROUGHPLASTIC_WIDTH)
    r = B.material_row(BSDF(type="plastic", int_ior=1.49, ext_ior=1.000277))
    assert r.shape == (L.MAT_WIDTH,) and r[L.MAT_ETA] == pytest.approx(1.49 / 1.000277)


STABILITY = [
    dict(type="diffuse"), dict(type="conductor"), dict(type="dielectric", int_ior=1.0, ext_ior=1.0),
    dict(type="dielectric"), dict(type="plastic"), dict(type="plastic", int_ior=1.0001, ext_ior=1.0),
]
for _d in ("beckmann", "ggx"):
    for _a in (1e-4, 0.05, 1.0):
        STABILITY += [dict(type="roughconductor", distribution=_d, alpha=_a),
                      dict(type="roughdielectric", distribution=_d, alpha=_a),
                      dict(type="roughdielectric", distribution=_d, alpha=_a, int_ior=1.0001, ext_ior=1.0),
                      dict(type="roughplastic", distribution=_d, alpha=_a)]


@pytest.mark.parametrize("kw", STABILITY, ids=[f"{k['type']}-{k.get('distribution', '')}-{k.get('alpha', '')}"
                                              f"-{k.get('int_ior', '')}" for k in STABILITY])
def test_stability_finite_and_bounded(kw):
    """alpha = 1e-4, grazing wi (cos = 1e-6), normal incidence, eta = 1 (smooth; 1.0001 rough: Mitsuba
    refuses an index-matched rough interface), wo = -wi and wo in the
    tangent plane: every output finite, weights bounded (<= 5: the largest legitimate weight is a
    refraction into a thinner medium, eta^2 = 2.26, or a plastic's diffuse weight 1 / (1 - F_int))."""
    row = row_of(**kw)
    u = np.random.default_rng(0).random((2000, 3))
    for ci in (1.0, 0.5, 1e-6, 0.0, -1e-6, -0.7, -1.0):
        wi = wi_at(ci)
        wo, w, pdf, delta = _sample_many(row, wi, u)
        assert np.all(np.isfinite(wo)) and np.all(np.isfinite(w)) and np.all(np.isfinite(pdf))
        assert np.all(w >= 0) and np.all(w <= 5.0) and np.all(pdf >= 0)
        probes = np.array([[-wi[0], -wi[1], -wi[2]], [-wi[0], -wi[1], wi[2]], [1.0, 0, 0], [0, 0, 1.0],
                           [0, 0, -1.0], list(wi)])
        probes = np.vstack([probes, wo[:200]])
        f, p = _eval_pdf_many(row, wi, probes)
        assert np.all(np.isfinite(f)) and np.all(np.isfinite(p)) and np.all(f >= 0) and np.all(p >= 0)


def test_sampled_lobe_class_of_roughplastic():
    """The class follows the lobe the sampler picked: for u_lobe below the coating probability the
    sample comes from the microfacet lobe (checked: wo is near the mirror direction for small alpha)."""
    th = L.ROUGHNESS_THRESHOLD
    wi = wi_at(0.5)
    for alpha, spec_class in ((0.3, L.V_GLOSSY), (0.01, L.V_SPECULAR)):
        row = row_of(type="roughplastic", alpha=alpha, reflectance=rgb(0.4), int_ior=1.5, ext_ior=1.0)
        assert B.sampled_lobe_class(row, wi, 0.0, False, th) == spec_class
        assert B.sampled_lobe_class(row, wi, 0.999, False, th) == L.V_DIFFUSE
        if alpha == 0.01:
            wo = B.bsdf_sample(row, wi, 0.0, 0.3, 0.6)[0]
            assert np.dot(wo, [-wi[0], -wi[1], wi[2]]) > 0.99
    assert B.sampled_lobe_class(row_of(type="plastic"), wi, 0.0, True, th) == L.V_SPECULAR
    assert B.sampled_lobe_class(row_of(type="diffuse"), wi, 0.0, False, th) == L.V_DIFFUSE


RECIPROCAL = [dict(type="diffuse", reflectance=rgb(0.3, 0.6, 0.9)),
              dict(type="roughconductor", distribution="ggx", alpha=0.3),
              dict(type="roughconductor", alpha=0.2),
              dict(type="roughdielectric", distribution="ggx", alpha=0.3),
              dict(type="plastic", reflectance=rgb(0.3, 0.6, 0.9), int_ior=1.49),
              dict(type="roughplastic", alpha=0.25, reflectance=rgb(0.3, 0.6, 0.9), int_ior=1.49)]


@pytest.mark.parametrize("kw", RECIPROCAL, ids=[k["type"] + "-" + k.get("distribution", "") for k in RECIPROCAL])
def test_reflection_is_reciprocal(kw):
    """Helmholtz reciprocity of the reflection lobes: f(wi, wo) = f(wo, wi), i.e.
    eval(wi, wo) / cos(wo) == eval(wo, wi) / cos(wi) (a physical check independent of Mitsuba)."""
    row = row_of(**kw)
    rng = np.random.default_rng(9)
    d = rng.normal(size=(400, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    d[:, 2] = np.abs(d[:, 2]) + 1e-3
    d /= np.linalg.norm(d, axis=1)[:, None]
    for wi, wo in zip(d[:200], d[200:]):
        a = np.array(B.bsdf_eval(row, tuple(wi), tuple(wo))) / wo[2]
        b = np.array(B.bsdf_eval(row, tuple(wo), tuple(wi))) / wi[2]
        np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-300)
