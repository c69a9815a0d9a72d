"""Dielectrics: ``dielectric`` (smooth interface, two delta lobes) and ``roughdielectric`` (Walter et
al. 2007 microfacet reflection + refraction), Mitsuba 3 plugins of the same names.

MAT_ETA = int_ior / ext_ior; a query with wi.z < 0 arrives from inside, where the relative index is
1 / eta (dielectrics are two-sided by nature). MAT_SR and MAT_ST scale reflection and transmission.
The lobe is chosen with probability F (reflection) or 1 - F (refraction), F the dielectric Fresnel
reflectance at the (micro)facet.

Radiance transport (Veach 1997, Sec. 5.2): on refraction, radiance is scaled by eta_ti^2 =
(eta_incident / eta_transmitted)^2 -- Mitsuba's ``TransportMode::Radiance``. The path integrator's
Russian roulette undoes this with throughput * eta^2 (:func:`gdlearn.kernels.bsdf.dispatch.bsdf_eta`).

Rough transmission (Walter et al. 2007, Eq. 21, with the eta_ti^2 radiance factor):
    f |cos wo| = |(wi.h)(wo.h)| eta^2 (1 - F) D G / (|cos wi| (wi.h + eta wo.h)^2) * eta_ti^2
with h = normalize(wi + eta wo) (Eq. 16) and the refraction Jacobian
    |dh/dwo| = eta^2 |wo.h| / (wi.h + eta wo.h)^2 (Eq. 17).
"""
import math


from gdlearn.kernels.bsdf.fresnel import fresnel_dielectric, reflect, reflect_m, refract, refract_m
from gdlearn.kernels.layout import MAT_ALPHA, MAT_DIST, MAT_ETA, MAT_SR, MAT_ST
from gdlearn.kernels.bsdf.microfacet import mf_D, mf_G, mf_G1, mf_pdf, mf_sample
from gdlearn.kernels.jit import block, inlined

ZERO3 = (0.0, 0.0, 0.0)


@inlined
def dielectric_sample(mat, wi, u_lobe):
    """Smooth interface: reflect with probability F, else refract (both delta lobes).
    Returns (wo, weight, pdf, True) with pdf the discrete lobe probability."""
    eta = mat[MAT_ETA]
    f, cos_t, eta_it, eta_ti = fresnel_dielectric(wi[2], eta)
    if u_lobe <= f:
        if f <= 0.0:
            return ZERO3, ZERO3, 0.0, True
        return reflect(wi), (mat[MAT_SR], mat[MAT_SR + 1], mat[MAT_SR + 2]), f, True
    if 1.0 - f <= 0.0:
        return ZERO3, ZERO3, 0.0, True
    s = eta_ti * eta_ti
    return (refract(wi, cos_t, eta_ti), (mat[MAT_ST] * s, mat[MAT_ST + 1] * s, mat[MAT_ST + 2] * s),
            1.0 - f, True)


@inlined
def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@block
def roughdielectric_sample(mat, wi, u_lobe, u1, u2):
    """Sample a visible normal for the side wi is on, then reflect (prob. F) or refract through it.
    Samples that end on the wrong side of the macro-surface (masked: G1(wo, m) = 0) are invalid."""
    cos_i = wi[2]
    if cos_i == 0.0:
        return ZERO3, ZERO3, 0.0, False
    dist, alpha, eta = int(mat[MAT_DIST]), mat[MAT_ALPHA], mat[MAT_ETA]
    sgn = 1.0 if cos_i > 0.0 else -1.0
    m, pdf = mf_sample(dist, alpha, (wi[0] * sgn, wi[1] * sgn, wi[2] * sgn), u1, u2)
    if not pdf > 0.0:
        return ZERO3, ZERO3, 0.0, False
    dot_im = _dot(wi, m)
    f, cos_t, eta_it, eta_ti = fresnel_dielectric(dot_im, eta)
    if u_lobe <= f:
        wo = reflect_m(wi, m)
        dot_om = _dot(wo, m)
        if f <= 0.0 or wo[2] * cos_i <= 0.0 or dot_om == 0.0:
            return ZERO3, ZERO3, 0.0, False
        pdf *= f / (4.0 * abs(dot_om))
        g = mf_G1(dist, alpha, wo, m)
        w = (mat[MAT_SR] * g, mat[MAT_SR + 1] * g, mat[MAT_SR + 2] * g)
    else:
        wo = refract_m(wi, m, cos_t, eta_ti)
        dot_om = _dot(wo, m)
        den = dot_im + eta_it * dot_om
        if f >= 1.0 or wo[2] * cos_i >= 0.0 or den == 0.0:
            return ZERO3, ZERO3, 0.0, False
        pdf *= (1.0 - f) * abs(eta_it * eta_it * dot_om / (den * den))
        g = mf_G1(dist, alpha, wo, m) * eta_ti * eta_ti
        w = (mat[MAT_ST] * g, mat[MAT_ST + 1] * g, mat[MAT_ST + 2] * g)
    if not pdf > 0.0 or g == 0.0:
        return ZERO3, ZERO3, 0.0, False
    return wo, w, pdf, False


@block
def _generalized_half_vector(wi, wo, eta):
    """(m, reflect, eta_it, ok): Walter's generalised half vector, oriented to +z (Eq. 13 / 16)."""
    cos_i, cos_o = wi[2], wo[2]
    is_reflect = cos_i * cos_o > 0.0
    eta_it = eta if cos_i > 0.0 else 1.0 / eta
    k = 1.0 if is_reflect else eta_it
    hx, hy, hz = wi[0] + wo[0] * k, wi[1] + wo[1] * k, wi[2] + wo[2] * k
    n = math.sqrt(hx * hx + hy * hy + hz * hz)
    if n == 0.0:                          # wi == -eta wo: degenerate, no microfacet maps wi to wo
        return ZERO3, is_reflect, eta_it, False
    if hz < 0.0:
        n = -n
    return (hx / n, hy / n, hz / n), is_reflect, eta_it, True


@block
def roughdielectric_eval(mat, wi, wo):
    cos_i = wi[2]
    if cos_i == 0.0:
        return ZERO3
    dist, alpha, eta = int(mat[MAT_DIST]), mat[MAT_ALPHA], mat[MAT_ETA]
    m, is_reflect, eta_it, ok = _generalized_half_vector(wi, wo, eta)
    if not ok:
        return ZERO3
    d = mf_D(dist, alpha, m)
    if d == 0.0:
        return ZERO3
    dot_im, dot_om = _dot(wi, m), _dot(wo, m)
    f = fresnel_dielectric(dot_im, eta)[0]
    g = mf_G(dist, alpha, wi, wo, m)
    if is_reflect:
        v = f * d * g / (4.0 * abs(cos_i))
        return (mat[MAT_SR] * v, mat[MAT_SR + 1] * v, mat[MAT_SR + 2] * v)
    den = dot_im + eta_it * dot_om
    if den == 0.0:
        return ZERO3
    inv_eta = 1.0 / eta_it
    v = abs(inv_eta * inv_eta * (1.0 - f) * d * g * eta_it * eta_it * dot_im * dot_om
            / (cos_i * den * den))
    return (mat[MAT_ST] * v, mat[MAT_ST + 1] * v, mat[MAT_ST + 2] * v)


@block
def roughdielectric_pdf(mat, wi, wo):
    cos_i, cos_o = wi[2], wo[2]
    if cos_i == 0.0:
        return 0.0
    dist, alpha, eta = int(mat[MAT_DIST]), mat[MAT_ALPHA], mat[MAT_ETA]
    m, is_reflect, eta_it, ok = _generalized_half_vector(wi, wo, eta)
    if not ok:
        return 0.0
    dot_im, dot_om = _dot(wi, m), _dot(wo, m)
    # micro- and macro-surface must agree on the side (the G1 orientation test, as Mitsuba)
    if dot_im * cos_i <= 0.0 or dot_om * cos_o <= 0.0:
        return 0.0
    if is_reflect:
        jac = 1.0 / (4.0 * dot_om)
    else:
        den = dot_im + eta_it * dot_om
        if den == 0.0:
            return 0.0
        jac = eta_it * eta_it * dot_om / (den * den)
    sgn = 1.0 if cos_i > 0.0 else -1.0
    prob = mf_pdf(dist, alpha, (wi[0] * sgn, wi[1] * sgn, wi[2] * sgn), m)
    f = fresnel_dielectric(dot_im, eta)[0]
    prob *= f if is_reflect else 1.0 - f
    return abs(prob * jac)
