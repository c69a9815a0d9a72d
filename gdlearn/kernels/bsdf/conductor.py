"""Conductors: ``conductor`` (a perfect mirror) and ``roughconductor`` (Walter et al. 2007 microfacet
reflection with visible-normal sampling), Mitsuba 3 plugins of the same names.

gdlearn supports ``material="none"`` only: Mitsuba then uses eta = 0, k = 1, for which the conductor
Fresnel term is exactly 1 at every angle, so the BSDF is scaled by ``specular_reflectance`` (MAT_R)
alone. Both are one-sided (0 for wi.z <= 0).

Rough reflection (Walter et al. 2007, Eq. 20 with F = 1):
    f(wi, wo) |cos wo| = R D(h) G(wi, wo, h) / (4 cos wi),  h = normalize(wi + wo)
Visible-normal sampling gives pdf(wo) = D(h) G1(wi, h) / (4 cos wi) (Heitz & d'Eon 2014, Eq. 17 with
the reflection Jacobian 1 / (4 wo.h)), hence the sample weight R G1(wo, h).
"""
import math


from gdlearn.kernels.bsdf.fresnel import reflect, reflect_m
from gdlearn.kernels.layout import MAT_ALPHA, MAT_DIST, MAT_R
from gdlearn.kernels.bsdf.microfacet import mf_D, mf_G, mf_G1, mf_sample
from gdlearn.kernels.jit import block, inlined

ZERO3 = (0.0, 0.0, 0.0)


@inlined
def conductor_sample(mat, wi):
    """Perfect mirror: wo = reflect(wi), weight = R, discrete probability 1 (delta lobe)."""
    if wi[2] <= 0.0:
        return ZERO3, ZERO3, 0.0, True
    return reflect(wi), (mat[MAT_R], mat[MAT_R + 1], mat[MAT_R + 2]), 1.0, True


@inlined
def _half_vector(wi, wo):
    hx, hy, hz = wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]
    n = math.sqrt(hx * hx + hy * hy + hz * hz)
    if n == 0.0:
        return (0.0, 0.0, 0.0), False
    return (hx / n, hy / n, hz / n), True


@block
def roughconductor_sample(mat, wi, u1, u2):
    if wi[2] <= 0.0:
        return ZERO3, ZERO3, 0.0, False
    dist, alpha = int(mat[MAT_DIST]), mat[MAT_ALPHA]
    m, pdf_m = mf_sample(dist, alpha, wi, u1, u2)
    wo = reflect_m(wi, m)
    dot_om = wo[0] * m[0] + wo[1] * m[1] + wo[2] * m[2]
    if not pdf_m > 0.0 or wo[2] <= 0.0 or dot_om <= 0.0:
        return ZERO3, ZERO3, 0.0, False
    g1 = mf_G1(dist, alpha, wo, m)
    pdf = pdf_m / (4.0 * dot_om)
    return wo, (mat[MAT_R] * g1, mat[MAT_R + 1] * g1, mat[MAT_R + 2] * g1), pdf, False


@block
def roughconductor_eval(mat, wi, wo):
    if wi[2] <= 0.0 or wo[2] <= 0.0:
        return ZERO3
    h, ok = _half_vector(wi, wo)
    if not ok:
        return ZERO3
    dist, alpha = int(mat[MAT_DIST]), mat[MAT_ALPHA]
    d = mf_D(dist, alpha, h)
    if d == 0.0:
        return ZERO3
    s = d * mf_G(dist, alpha, wi, wo, h) / (4.0 * wi[2])
    return (mat[MAT_R] * s, mat[MAT_R + 1] * s, mat[MAT_R + 2] * s)


@block
def roughconductor_pdf(mat, wi, wo):
    if wi[2] <= 0.0 or wo[2] <= 0.0:
        return 0.0
    h, ok = _half_vector(wi, wo)
    if not ok:
        return 0.0
    if wi[0] * h[0] + wi[1] * h[1] + wi[2] * h[2] <= 0.0 or wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2] <= 0.0:
        return 0.0
    dist, alpha = int(mat[MAT_DIST]), mat[MAT_ALPHA]
    return mf_D(dist, alpha, h) * mf_G1(dist, alpha, wi, h) / (4.0 * wi[2])
