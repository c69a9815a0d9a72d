"""Plastics: a diffuse base under a dielectric coating -- Mitsuba 3's ``plastic`` (smooth coating:
a delta reflection lobe + a diffuse lobe) and ``roughplastic`` (microfacet coating + diffuse lobe).

Both follow Mitsuba exactly (src/bsdfs/plastic.cpp, roughplastic.cpp), including its
approximations (Weidlich & Wilkie 2007 style layering):

* diffuse part  f_d |cos wo| = R / (1 - k) * cos(wo) / pi * (1 / eta^2) * T_i * T_o,
  with k = F_int (linear) or R * F_int (``nonlinear``: internal bounces tint the base colour);
  smooth: T = 1 - F(cos) (Fresnel), F_int = ``fresnel_diffuse_reflectance(1 / eta)``;
  rough: T = the tabulated rough-interface transmittance (64 entries, linear interpolation in
  cos theta), F_int = 2 * mean over the table's directions of the rough internal reflectance * cos.
* specular part: smooth, F(cos wi) * SR as a delta lobe; rough, F(wi.h) D G / (4 cos wi) * SR.
* lobe selection: p_spec ~ F_i * w_s, p_diff ~ (1 - F_i) (1 - w_s) (rough: 1 - T_i and T_i), with the
  specular sampling weight w_s = mean(SR) / (mean(R) + mean(SR)).

Everything that depends only on the material is precomputed by :func:`prepare_plastic` into the
material row: MAT_AUX = F_int (smooth) / internal reflectance (rough), MAT_AUX + 1 = w_s, and for
``roughplastic`` the transmittance table in columns PLASTIC_TABLE .. PLASTIC_TABLE + TABLE_RES - 1.
"""
import functools
import math

import numpy as np


from gdlearn.kernels.bsdf.fresnel import fresnel_dielectric, fresnel_diffuse_reflectance, reflect, reflect_m, refract_m
from gdlearn.kernels.layout import (MAT_ALPHA, MAT_AUX, MAT_DIST, MAT_ETA, MAT_NONLINEAR, MAT_R, MAT_SR,
                                    MAT_TYPE, ROUGHPLASTIC)
from gdlearn.kernels.bsdf.microfacet import mf_D, mf_G1, mf_sample
from gdlearn.kernels.sampling import INV_PI, square_to_cosine_hemisphere
from gdlearn.kernels.jit import block, inlined

ZERO3 = (0.0, 0.0, 0.0)
AUX_FDR = MAT_AUX           # internal diffuse Fresnel reflectance
AUX_SPEC_WEIGHT = MAT_AUX + 1
TABLE_RES = 64              # Mitsuba's MI_ROUGH_TRANSMITTANCE_RES
PLASTIC_TABLE = MAT_AUX + 2
ROUGHPLASTIC_WIDTH = PLASTIC_TABLE + TABLE_RES   # row width a roughplastic needs


@block
def _diffuse_albedo(mat):
    """R / (1 - F_int) (linear) or R / (1 - R F_int) (nonlinear), per channel."""
    fdr = mat[AUX_FDR]
    nl = mat[MAT_NONLINEAR] != 0.0
    r0, r1, r2 = mat[MAT_R], mat[MAT_R + 1], mat[MAT_R + 2]
    if nl:
        return (r0 / (1.0 - r0 * fdr), r1 / (1.0 - r1 * fdr), r2 / (1.0 - r2 * fdr))
    k = 1.0 / (1.0 - fdr)
    return (r0 * k, r1 * k, r2 * k)


@block
def _spec_prob(f_spec, mat):
    """Probability of the specular lobe given its 'reflected fraction' f_spec (F_i or 1 - T_i)."""
    ws = mat[AUX_SPEC_WEIGHT]
    ps = f_spec * ws
    pd = (1.0 - f_spec) * (1.0 - ws)
    tot = ps + pd
    return ps / tot if tot > 0.0 else 0.0


# --- smooth plastic -------------------------------------------------------------------------------
@block
def plastic_sample(mat, wi, u_lobe, u1, u2):
    cos_i = wi[2]
    if cos_i <= 0.0:
        return ZERO3, ZERO3, 0.0, False
    eta = mat[MAT_ETA]
    f_i = fresnel_dielectric(cos_i, eta)[0]
    p_spec = _spec_prob(f_i, mat)
    if u_lobe < p_spec:
        v = f_i / p_spec
        return reflect(wi), (mat[MAT_SR] * v, mat[MAT_SR + 1] * v, mat[MAT_SR + 2] * v), p_spec, True
    p_diff = 1.0 - p_spec
    wo = square_to_cosine_hemisphere(u1, u2)
    pdf = p_diff * wo[2] * INV_PI
    if not pdf > 0.0:
        return ZERO3, ZERO3, 0.0, False
    f_o = fresnel_dielectric(wo[2], eta)[0]
    a = _diffuse_albedo(mat)
    s = (1.0 - f_i) * (1.0 - f_o) / (eta * eta * p_diff)
    return wo, (a[0] * s, a[1] * s, a[2] * s), pdf, False


@block
def plastic_eval(mat, wi, wo):
    if wi[2] <= 0.0 or wo[2] <= 0.0:
        return ZERO3
    eta = mat[MAT_ETA]
    f_i = fresnel_dielectric(wi[2], eta)[0]
    f_o = fresnel_dielectric(wo[2], eta)[0]
    a = _diffuse_albedo(mat)
    s = wo[2] * INV_PI * (1.0 - f_i) * (1.0 - f_o) / (eta * eta)
    return (a[0] * s, a[1] * s, a[2] * s)


@block
def plastic_pdf(mat, wi, wo):
    if wi[2] <= 0.0 or wo[2] <= 0.0:
        return 0.0
    f_i = fresnel_dielectric(wi[2], mat[MAT_ETA])[0]
    return (1.0 - _spec_prob(f_i, mat)) * wo[2] * INV_PI


# --- rough plastic --------------------------------------------------------------------------------
@block
def rough_transmittance(mat, cos_theta):
    """Mitsuba's ``lerp_gather`` of the tabulated external transmittance at cos_theta in [0, 1]."""
    x = cos_theta * (TABLE_RES - 1)
    idx = min(int(x), TABLE_RES - 2)
    w = x - idx
    v0 = mat[PLASTIC_TABLE + idx]
    v1 = mat[PLASTIC_TABLE + idx + 1]
    return v0 + (v1 - v0) * w


@block
def plastic_spec_prob(mat, cos_i):
    """Probability that plastic_sample picks the delta coating at incidence cos_i > 0."""
    return _spec_prob(fresnel_dielectric(cos_i, mat[MAT_ETA])[0], mat)


@block
def roughplastic_spec_prob(mat, cos_i):
    """Probability that roughplastic_sample picks the microfacet coating at incidence cos_i."""
    return _spec_prob(1.0 - rough_transmittance(mat, cos_i), mat)


@inlined
def _rough_coat(mat, wi, wo):
    """The coating's half vector h of wi, wo (both z > 0), D(h) and G1(wi, h): what the eval and the
    pdf share."""
    dist, alpha = int(mat[MAT_DIST]), mat[MAT_ALPHA]
    hx, hy, hz = wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]
    n = math.sqrt(hx * hx + hy * hy + hz * hz)      # > 0 since both z > 0
    h = (hx / n, hy / n, hz / n)
    return h, mf_D(dist, alpha, h), mf_G1(dist, alpha, wi, h)


@inlined
def _rough_f(mat, wi, wo, h, d, g1_i, t_i):
    """f |cos wo| of the rough plastic given :func:`_rough_coat`'s h, D, G1(wi) and the external
    transmittance t_i at wi: the coating's Fresnel-weighted microfacet term plus the base's
    diffuse term through both interfaces."""
    cos_i, cos_o = wi[2], wo[2]
    eta = mat[MAT_ETA]
    spec = 0.0
    if d > 0.0:
        f = fresnel_dielectric(wi[0] * h[0] + wi[1] * h[1] + wi[2] * h[2], eta)[0]
        # mf_G's separable G1(wi) G1(wo), in its order
        spec = f * d * (g1_i * mf_G1(int(mat[MAT_DIST]), mat[MAT_ALPHA], wo, h)) / (4.0 * cos_i)
    t_o = rough_transmittance(mat, cos_o)
    a = _diffuse_albedo(mat)
    s = cos_o * INV_PI / (eta * eta) * t_i * t_o
    return (mat[MAT_SR] * spec + a[0] * s, mat[MAT_SR + 1] * spec + a[1] * s,
            mat[MAT_SR + 2] * spec + a[2] * s)


@inlined
def _rough_pdf_parts(d, g1_i, cos_i, cos_o, p_spec):
    """(coating, base) parts of the pdf, lobe-selection probabilities included."""
    spec = d * g1_i / (4.0 * cos_i)
    return spec * p_spec, (1.0 - p_spec) * cos_o * INV_PI


@block
def roughplastic_eval(mat, wi, wo):
    if wi[2] <= 0.0 or wo[2] <= 0.0:
        return ZERO3
    h, d, g1_i = _rough_coat(mat, wi, wo)
    return _rough_f(mat, wi, wo, h, d, g1_i, rough_transmittance(mat, wi[2]))


@block
def roughplastic_eval_pdf(mat, wi, wo):
    """(:func:`roughplastic_eval`, :func:`roughplastic_pdf`) at once, the shared terms computed once
    (the same values: next-event estimates and :func:`roughplastic_sample` need both)."""
    cos_i, cos_o = wi[2], wo[2]
    if cos_i <= 0.0 or cos_o <= 0.0:
        return ZERO3, 0.0
    h, d, g1_i = _rough_coat(mat, wi, wo)
    t_i = rough_transmittance(mat, cos_i)
    coat, base = _rough_pdf_parts(d, g1_i, cos_i, cos_o, _spec_prob(1.0 - t_i, mat))
    return _rough_f(mat, wi, wo, h, d, g1_i, t_i), coat + base


@inlined
def _roughplastic_pdf_parts(mat, wi, wo):
    """(coating, base) parts of roughplastic_pdf, lobe-selection probabilities included."""
    cos_i, cos_o = wi[2], wo[2]
    if cos_i <= 0.0 or cos_o <= 0.0:
        return 0.0, 0.0
    p_spec = roughplastic_spec_prob(mat, cos_i)
    h, d, g1_i = _rough_coat(mat, wi, wo)
    return _rough_pdf_parts(d, g1_i, cos_i, cos_o, p_spec)


@block
def roughplastic_pdf(mat, wi, wo):
    coat, base = _roughplastic_pdf_parts(mat, wi, wo)
    return coat + base


@block
def roughplastic_coat_fraction(mat, wi, wo):
    """The share of roughplastic_pdf(wi, wo) that comes from the microfacet coating: the posterior
    probability that roughplastic_sample picked the coating, given that it produced wo.

    Effects-restricted renders split a rough plastic's next-event term by this share (coating part
    -> glossy class, the rest -> diffuse), the same partition the sampled lobe realises for BSDF
    samples, so both MIS strategies estimate the same per-class integrand. 0 where the pdf is 0."""
    coat, base = _roughplastic_pdf_parts(mat, wi, wo)
    total = coat + base
    if not total > 0.0:
        return 0.0
    return coat / total


@block
def roughplastic_sample(mat, wi, u_lobe, u1, u2):
    """Pick a lobe, sample its direction, then weight by the full mixture (eval / pdf), as Mitsuba."""
    cos_i = wi[2]
    if cos_i <= 0.0:
        return ZERO3, ZERO3, 0.0, False
    p_spec = roughplastic_spec_prob(mat, cos_i)
    if u_lobe < p_spec:
        m = mf_sample(int(mat[MAT_DIST]), mat[MAT_ALPHA], wi, u1, u2)[0]
        wo = reflect_m(wi, m)
    else:
        wo = square_to_cosine_hemisphere(u1, u2)
    f, pdf = roughplastic_eval_pdf(mat, wi, wo)
    if not pdf > 0.0:
        return ZERO3, ZERO3, 0.0, False
    inv = 1.0 / pdf
    return wo, (f[0] * inv, f[1] * inv, f[2] * inv), pdf, False


# --- precomputation (once per material, at scene compile time) ----------------------------------
@block
def _rough_table(dist, alpha, eta, nodes, weights, mu):
    """External transmittance T(mu) and internal reflectance, by Gauss-Legendre quadrature over the
    visible-normal sample space (Mitsuba's ``eval_transmittance`` / ``eval_reflectance``)."""
    out = np.zeros(mu.shape[0])
    n = nodes.shape[0]
    for k in range(mu.shape[0]):
        wi = (math.sqrt(max(0.0, 1.0 - mu[k] * mu[k])), 0.0, mu[k])
        acc = 0.0
        for i in range(n):
            for j in range(n):
                m = mf_sample(dist, alpha, wi, nodes[i] * 0.5 + 0.5, nodes[j] * 0.5 + 0.5)[0]
                dot_im = wi[0] * m[0] + wi[1] * m[1] + wi[2] * m[2]
                f, cos_t, eta_it, eta_ti = fresnel_dielectric(dot_im, eta)
                wo = refract_m(wi, m, cos_t, eta_ti)
                if wo[2] * wi[2] < 0.0:
                    acc += mf_G1(dist, alpha, wo, m) * (1.0 - f) * weights[i] * weights[j] * 0.25
        out[k] = acc
    return out


@block
def _rough_reflectance(dist, alpha, eta, nodes, weights, mu):
    out = np.zeros(mu.shape[0])
    n = nodes.shape[0]
    for k in range(mu.shape[0]):
        wi = (math.sqrt(max(0.0, 1.0 - mu[k] * mu[k])), 0.0, mu[k])
        acc = 0.0
        for i in range(n):
            for j in range(n):
                m = mf_sample(dist, alpha, wi, nodes[i] * 0.5 + 0.5, nodes[j] * 0.5 + 0.5)[0]
                wo = reflect_m(wi, m)
                if wo[2] > 0.0 and wi[2] > 0.0:
                    f = fresnel_dielectric(wi[0] * m[0] + wi[1] * m[1] + wi[2] * m[2], eta)[0]
                    acc += mf_G1(dist, alpha, wo, m) * f * weights[i] * weights[j] * 0.25
        out[k] = acc
    return out


def prepare_plastic(row: np.ndarray) -> None:
    """Fill the precomputed columns of a plastic / roughplastic row in place (see module doc)."""
    r = row[MAT_R:MAT_R + 3]
    sr = row[MAT_SR:MAT_SR + 3]
    d_mean, s_mean = float(np.mean(r)), float(np.mean(sr))
    row[AUX_SPEC_WEIGHT] = s_mean / (d_mean + s_mean) if d_mean + s_mean > 0 else 0.5
    eta = float(row[MAT_ETA])
    if int(row[MAT_TYPE]) != ROUGHPLASTIC:
        row[AUX_FDR] = fresnel_diffuse_reflectance(1.0 / eta)
        return
    if row.shape[0] < ROUGHPLASTIC_WIDTH:
        raise ValueError(f"a roughplastic material row needs {ROUGHPLASTIC_WIDTH} columns (its rough "
                         f"transmittance table), got {row.shape[0]}; fix: build it with material_row(bsdf, "
                         f"width={ROUGHPLASTIC_WIDTH}) (scene/compile.py widens the table when needed)")
    table, internal = rough_plastic_tables(int(row[MAT_DIST]), max(float(row[MAT_ALPHA]), 1e-4), eta)
    row[PLASTIC_TABLE:PLASTIC_TABLE + TABLE_RES] = table
    row[AUX_FDR] = internal


@functools.lru_cache(maxsize=64)
def rough_plastic_tables(dist: int, alpha: float, eta: float):
    """(external transmittance table (TABLE_RES,), internal diffuse reflectance) of a rough dielectric
    coating, as Mitsuba's ``RoughPlastic::parameters_changed``: T at mu = max(1e-6, linspace(0, 1, 64))
    by Gauss-Legendre quadrature (32^2 nodes when eta > 1, else 128^2) over the visible-normal sample
    space, and F_int = 2 * mean(R_internal(mu) * mu). Cached: materials often share (dist, alpha, eta),
    and a Beckmann table costs ~1-2 s."""
    mu = np.maximum(1e-6, np.linspace(0.0, 1.0, TABLE_RES))
    res = 32 if eta > 1.0 else 128
    nodes, weights = np.polynomial.legendre.leggauss(res)
    table = _rough_table(dist, alpha, eta, nodes, weights, mu)
    inv = 1.0 / eta
    res = 32 if inv > 1.0 else 128
    nodes, weights = np.polynomial.legendre.leggauss(res)
    refl = _rough_reflectance(dist, alpha, inv, nodes, weights, mu)
    table.setflags(write=False)
    return table, 2.0 * float(np.mean(refl * mu))
