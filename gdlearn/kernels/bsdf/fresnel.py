"""Fresnel equations, mirror reflection and refraction in the local shading frame (normal = +z).

Follows Mitsuba 3's ``mitsuba/render/fresnel.h``: ``eta`` is the relative index int_ior / ext_ior;
a value above 1 means the normal points into the optically thinner side. Directions point away from
the surface (``wi`` towards where the path came from), so refraction of ``wi`` gives the outgoing
direction on the other side.
"""
import math
from gdlearn.kernels.jit import block, ir_inline



@block
def fresnel_dielectric(cos_theta_i, eta):
    """Unpolarised Fresnel reflectance of a dielectric interface (Mitsuba's ``fresnel``).

    Returns ``(F, cos_theta_t, eta_it, eta_ti)``: the reflectance, the signed cosine of the
    transmitted direction (opposite side to ``cos_theta_i``; 0 under total internal reflection),
    the relative index in the direction of travel and its reciprocal (the scale of the x, y
    components of the refracted direction). ``cos_theta_i < 0`` means the ray arrives from inside.
    """
    outside = cos_theta_i >= 0.0
    eta_it = eta if outside else 1.0 / eta
    eta_ti = 1.0 / eta if outside else eta
    # Snell: cos^2 t = 1 - eta_ti^2 sin^2 i (negative: total internal reflection)
    cos_t_sqr = 1.0 - (1.0 - cos_theta_i * cos_theta_i) * (eta_ti * eta_ti)
    ci = abs(cos_theta_i)
    ct = math.sqrt(cos_t_sqr) if cos_t_sqr > 0.0 else 0.0
    cos_theta_t = -ct if cos_theta_i >= 0.0 else ct
    if eta == 1.0:                       # index-matched: no interface at all
        return 0.0, cos_theta_t, eta_it, eta_ti
    if ci == 0.0:                        # grazing: everything is reflected
        return 1.0, cos_theta_t, eta_it, eta_ti
    a_s = (ci - eta_it * ct) / (ci + eta_it * ct)
    a_p = (ct - eta_it * ci) / (ct + eta_it * ci)
    return 0.5 * (a_s * a_s + a_p * a_p), cos_theta_t, eta_it, eta_ti


@block
def fresnel_diffuse_reflectance(eta):
    """Diffuse Fresnel reflectance F_dr: the fraction of uniformly diffuse illumination reflected by
    the interface (Mitsuba's ``fresnel_diffuse_reflectance``: Egan & Hilgeman 1973 fit for eta < 1,
    d'Eon & Irving 2011 polynomial in 1/eta otherwise). Used by the plastic model's internal
    reflection term."""
    inv = 1.0 / eta
    if eta < 1.0:
        return 0.0636 * inv + (eta * (eta * -1.4399 + 0.7099) + 0.6681)
    # Horner: 0.919317 - 3.4793 x + 6.75335 x^2 - 7.80989 x^3 + 4.98554 x^4 - 1.36881 x^5
    return 0.919317 + inv * (-3.4793 + inv * (6.75335 + inv * (-7.80989 + inv * (4.98554 - inv * 1.36881))))


@ir_inline
def reflect(wi):
    """Mirror reflection about the normal +z."""
    return (-wi[0], -wi[1], wi[2])


@ir_inline
def reflect_m(wi, m):
    """Mirror reflection of wi about the microfacet normal m: 2 (wi.m) m - wi."""
    d = 2.0 * (wi[0] * m[0] + wi[1] * m[1] + wi[2] * m[2])
    return (m[0] * d - wi[0], m[1] * d - wi[1], m[2] * d - wi[2])


@ir_inline
def refract(wi, cos_theta_t, eta_ti):
    """Refraction about +z, with cos_theta_t and eta_ti from :func:`fresnel_dielectric`."""
    return (-eta_ti * wi[0], -eta_ti * wi[1], cos_theta_t)


@ir_inline
def refract_m(wi, m, cos_theta_t, eta_ti):
    """Refraction of wi through the microfacet normal m: m ((wi.m) eta_ti + cos_t) - wi eta_ti."""
    s = (wi[0] * m[0] + wi[1] * m[1] + wi[2] * m[2]) * eta_ti + cos_theta_t
    return (m[0] * s - wi[0] * eta_ti, m[1] * s - wi[1] * eta_ti, m[2] * s - wi[2] * eta_ti)
