"""Emission sampling for light paths: an emitter chosen by power, then a position and a direction.

Light tracing starts a path at y0 on an emitter with the weight ``Le(y0 -> y1) cos / (p_A(y0)
p_sigma(w))`` (Veach 1997, Sec. 10.2; pbrt-v3 ``SPPMIntegrator`` photon pass), the power the path
carries in units of flux per emitted path. Every emitter type of the supported subset
(:mod:`!gdlearn.kernels.lights`, Mitsuba 3 semantics):

==============  ============================================  =================================
type            position (area-measure pdf)                   direction (solid-angle pdf)
==============  ============================================  =================================
area            uniform on the shape, 1 / A                   cosine about the normal, cos / pi
point           delta at the light                            uniform sphere, 1 / (4 pi)
spot            delta at the light                            uniform in the cutoff cone
directional     uniform on a disc of radius r_bs across the   delta along ``direction``
                scene's bounding sphere, 1 / (pi r_bs^2)
constant        the same disc, perpendicular to the sampled   uniform sphere, 1 / (4 pi)
                direction, 1 / (pi r_bs^2)
==============  ============================================  =================================

The emitter is chosen with probability proportional to its power (``fluxLightDensity`` of the
reference photon mappers; pbrt-v3 ``ComputeLightPowerDistribution``). Any positive choice is
unbiased -- the weight divides by it -- the power only makes the photons' weights even. A spot's
power is taken over its whole cone (an upper bound of the falloff), which is just as valid.
"""
from __future__ import annotations

import math

import numpy as np


from gdlearn.kernels import lights as li
from gdlearn.kernels.lights import pick_prim, prim_point, spot_falloff
from gdlearn.kernels.sampling import square_to_uniform_cone, square_to_uniform_disk_concentric
from gdlearn.kernels.vec import coordinate_system, to_world
from gdlearn.kernels.jit import block, inlined


def emitter_power(sa) -> np.ndarray:
    """Power (mean over RGB) of every emitter row of ``sa``, the unnormalised selection weights."""
    em = sa.emitters
    out = np.zeros(em.shape[0])
    r = float(sa.bsphere[3])
    for i in range(em.shape[0]):
        t = int(em[i, li.EM_TYPE])
        le = float(np.mean(em[i, li.EM_RGB:li.EM_RGB + 3]))
        if t == li.E_AREA:
            out[i] = math.pi * em[i, li.EM_AREA] * le
        elif t == li.E_POINT:
            out[i] = 4.0 * math.pi * le
        elif t == li.E_SPOT:
            out[i] = 2.0 * math.pi * (1.0 - em[i, li.EM_COS_CUTOFF]) * le
        elif t == li.E_DIRECTIONAL:
            out[i] = math.pi * r * r * le
        else:
            out[i] = 4.0 * math.pi * math.pi * r * r * le
    return out


def emitter_cdf(sa) -> np.ndarray:
    """Normalised cumulative power of the emitters (``cdf[-1] == 1``); uniform if all are black.
    Raises ValueError when the scene has no emitter (no light path can start)."""
    p = emitter_power(sa)
    if p.size == 0:
        raise ValueError("the scene has no emitter, so no light path can start; fix: add an emitter")
    if not p.sum() > 0:
        p = np.ones_like(p)
    c = np.cumsum(p) / p.sum()
    c[-1] = 1.0
    return c


@inlined
def _select(cdf, u):
    """(index, probability, leftover uniform in [0, 1)) of the first cdf entry > u."""
    i = pick_prim(cdf, 0, cdf.shape[0], u)
    lo = cdf[i - 1] if i > 0 else 0.0
    p = cdf[i] - lo
    rest = min((u - lo) / p, 0.9999999999999999) if p > 0.0 else 0.0
    return i, p, rest


@block
def sample_emission(sa, cdf, u):
    """Start of a light path from the 5 uniforms ``u`` (selection, 2 position, 2 direction).

    Returns (em, prim, p, n, d, weight, pdf_pos, pdf_dir, delta_pos, delta_dir): the emitter row,
    its primitive (-1 unless area), the position y0 and its normal (the disc's normal for
    directional / constant, zeros for point and spot), the unit direction of travel, the weight
    Le cos / (p_sel p_A p_sigma) (rgb), the area-measure pdf of y0 (selection included), the
    solid-angle pdf of d, and whether either is a Dirac delta (its "pdf" is then 1).
    ``em = -1`` when the sample carries nothing (a black emitter, a zero-probability choice).
    """
    zero = (0.0, 0.0, 0.0)
    em, sel, u_rest = _select(cdf, u[0])
    if not sel > 0.0:
        return -1, -1, zero, zero, zero, zero, 0.0, 0.0, False, False
    et = int(sa.emitters[em, li.EM_TYPE])
    rgb = (sa.emitters[em, li.EM_RGB], sa.emitters[em, li.EM_RGB + 1], sa.emitters[em, li.EM_RGB + 2])
    if et == li.E_AREA:
        prim = sa.em_prims[pick_prim(sa.em_cdf, int(sa.emitters[em, li.EM_FIRST]),
                                      int(sa.emitters[em, li.EM_COUNT]), u_rest)]
        p, n = prim_point(sa.prims, sa.prim_info, prim, u[1], u[2])
        s, t = coordinate_system(n)
        r = math.sqrt(u[3])                       # cosine-weighted hemisphere about n (one-sided)
        phi = 2.0 * math.pi * u[4]
        cz = math.sqrt(max(0.0, 1.0 - u[3]))
        d = to_world((r * math.cos(phi), r * math.sin(phi), cz), s, t, n)
        pdf_pos = sel / sa.emitters[em, li.EM_AREA]
        if not cz > 0.0:
            return -1, -1, zero, zero, zero, zero, 0.0, 0.0, False, False
        f = math.pi / pdf_pos                     # Le cos / (p_A cos / pi)
        return em, prim, p, n, d, (rgb[0] * f, rgb[1] * f, rgb[2] * f), pdf_pos, cz / math.pi, False, False
    if et == li.E_POINT or et == li.E_SPOT:
        p = (sa.emitters[em, li.EM_P], sa.emitters[em, li.EM_P + 1], sa.emitters[em, li.EM_P + 2])
        if et == li.E_POINT:
            z = 1.0 - 2.0 * u[3]
            rr = math.sqrt(max(0.0, 1.0 - z * z))
            phi = 2.0 * math.pi * u[4]
            d = (rr * math.cos(phi), rr * math.sin(phi), z)
            pdf_dir = 0.25 / math.pi
            f = 1.0 / (sel * pdf_dir)
        else:
            cc = sa.emitters[em, li.EM_COS_CUTOFF]
            dl = square_to_uniform_cone(u[3], u[4], cc)
            # the spot's local frame: world = inverse(EM_INV) applied to local; EM_INV is orthonormal
            # up to scale for rigid transforms, so its transpose maps local to world directions
            m = sa.emitters[em, li.EM_INV:li.EM_INV + 9]
            d = _normalized((m[0] * dl[0] + m[3] * dl[1] + m[6] * dl[2], m[1] * dl[0] + m[4] * dl[1] + m[7] * dl[2],
                             m[2] * dl[0] + m[5] * dl[1] + m[8] * dl[2]))
            pdf_dir = 1.0 / (2.0 * math.pi * (1.0 - cc))
            f = spot_falloff(sa.emitters, em, d) / (sel * pdf_dir)
            if not f > 0.0:
                return -1, -1, zero, zero, zero, zero, 0.0, 0.0, True, False
        return em, -1, p, zero, d, (rgb[0] * f, rgb[1] * f, rgb[2] * f), sel, pdf_dir, True, False
    return _sample_far(sa, em, sel, rgb, et, u)


@inlined
def _normalized(v):
    n = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    return (v[0] / n, v[1] / n, v[2] / n) if n > 0.0 else (0.0, 0.0, 1.0)


@inlined
def _sample_far(sa, em, sel, rgb, et, u):
    """Directional and constant emitters: a point on the disc of radius r_bs, centred r_bs behind
    the bounding sphere's centre and facing the direction of travel (pbrt-v3 ``InfiniteAreaLight::
    Sample_Le``); every ray of that bundle crosses the whole scene."""
    c = (sa.bsphere[0], sa.bsphere[1], sa.bsphere[2])
    r = sa.bsphere[3]
    if et == li.E_DIRECTIONAL:
        d = (sa.emitters[em, li.EM_D], sa.emitters[em, li.EM_D + 1], sa.emitters[em, li.EM_D + 2])
        pdf_dir = 1.0
    else:
        z = 1.0 - 2.0 * u[3]
        rr = math.sqrt(max(0.0, 1.0 - z * z))
        phi = 2.0 * math.pi * u[4]
        d = (rr * math.cos(phi), rr * math.sin(phi), z)
        pdf_dir = 0.25 / math.pi
    s, t = coordinate_system(d)
    dx, dy = square_to_uniform_disk_concentric(u[1], u[2])
    p = (c[0] + r * (dx * s[0] + dy * t[0] - d[0]), c[1] + r * (dx * s[1] + dy * t[1] - d[1]),
         c[2] + r * (dx * s[2] + dy * t[2] - d[2]))
    pdf_pos = sel / (math.pi * r * r)
    f = 1.0 / (pdf_pos * pdf_dir)
    return em, -1, p, d, d, (rgb[0] * f, rgb[1] * f, rgb[2] * f), pdf_pos, pdf_dir, False, et == li.E_DIRECTIONAL
