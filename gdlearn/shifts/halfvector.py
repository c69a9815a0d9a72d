"""Half-vector copy (STAR, Hua et al. 2019, Sec. 3.2, Eq. 15; Kettunen et al. 2015) for reflection and
refraction, with its Jacobian in the solid-angle measure and, via GPM 2017 Eq. 4, the area measure.

At vertex k the base path arrives from w_i and leaves along w_o; the offset path arrives at x'_k from
w'_i. The shift keeps the half vector in the local shading frame (Eq. 15), h' = h, and solves for w'_o.
With Walter et al.'s (2007) generalised half vector every event is one formula:

    h = normalize(w_i + k w_o),   k = 1 (reflection),  k = eta_it (refraction, eta_it = eta_t / eta_i)

oriented to the +z hemisphere (Mitsuba 3's roughdielectric convention), and the density change of
w_o -> h is (Walter et al. 2007, Eq. 14 and 16)

    |dh/dw_o| = k^2 |w_o . h| / (w_i . h + k w_o . h)^2       (= 1 / (4 |w_o . h|) for k = 1).

Because h' = h (the frame change is a rotation, measure-preserving),

    J_w = |dw'_o/dw_o| = |dh/dw_o|(base) / |dh/dw'_o|(offset),

which for reflection is |w'_o . h| / |w_o . h| (Kettunen et al. 2015, supplement). The area-measure
Jacobian of the next vertex is J_w times the change of measure dA = d^2/|cos| dw on both paths
(:func:`gdlearn.shifts.path.jacobian_solid_angle_to_area`, GPM Eq. 4).

Delta lobes: at a smooth conductor / dielectric the direction is not a free variable (its density
is a discrete lobe probability), so the factor is 1 there (:func:`halfvector_copy_mat`); the
direction mapping is the same.

Failures (flag, never an exception): degenerate half vector (w_i = -w_o with k = 1, i.e. a
"transmission" through a reflector or an index-matched refraction), total internal reflection on
the offset, an offset direction on the wrong side of the macro- or microsurface (zero BSDF), a
non-finite Jacobian. Refraction through an index-matched interface (eta = 1) has no half vector at
all: it is a straight pass-through, shifted as w'_o = -w'_i with J = 1.
"""
import math


from gdlearn.kernels import layout as L
from gdlearn.kernels import vec
from gdlearn.kernels.bsdf.fresnel import fresnel_dielectric, refract_m
from gdlearn.kernels.jit import block, ir_inline, leaf

ZERO3 = (0.0, 0.0, 0.0)
#: |w_i + k w_o| below this (relative to 1 + k) is a degenerate half vector: h's direction would be
#: dominated by round-off (its error is ~eps / |w_i + k w_o|).
DEGENERATE_H = 1e-9


@leaf
def half_vector(wi, wo, eta):
    """``(h, k, ok)``: Walter's generalised half vector of (wi, wo) in the local frame, +z oriented;
    k = 1 for reflection (wi, wo on one side), eta_it for refraction through relative index eta."""
    refl = wi[2] * wo[2] > 0.0
    k = 1.0 if refl else (eta if wi[2] > 0.0 else 1.0 / eta)
    h = (wi[0] + k * wo[0], wi[1] + k * wo[1], wi[2] + k * wo[2])
    n = vec.norm(h)
    if not n > DEGENERATE_H * (1.0 + k):
        return ZERO3, k, False
    if h[2] < 0.0:
        n = -n
    return vec.scale(h, 1.0 / n), k, True


@ir_inline
def dh_dwo(wi, wo, h, k):
    """|dh/dw_o| of the generalised half vector (Walter et al. 2007 Eq. 14 / 16); 0 if degenerate."""
    den = vec.dot(wi, h) + k * vec.dot(wo, h)
    if den == 0.0:
        return 0.0
    return k * k * abs(vec.dot(wo, h)) / (den * den)


@ir_inline
def outgoing(wi, h, eta, refract):
    """``(wo, k, ok)``: the direction leaving a vertex of half vector h (local frame, +z; ``wi``
    pointing away from the vertex) by reflection or by refraction through relative index eta
    (int/ext), the inverse of :func:`half_vector`, with its k. Not ok under total internal
    reflection, or where a direction lies on the wrong side of the macro- or microsurface."""
    ci = vec.dot(wi, h)
    if refract:
        _, cos_t, eta_it, eta_ti = fresnel_dielectric(ci, eta)
        if cos_t == 0.0:                   # total internal reflection (or exactly grazing)
            return ZERO3, 1.0, False
        wo = vec.normalize(refract_m(wi, h, cos_t, eta_ti))
        k = eta_it
        if not (wo[2] * wi[2] < 0.0):
            return ZERO3, 1.0, False
    else:
        wo = (2.0 * ci * h[0] - wi[0], 2.0 * ci * h[1] - wi[1], 2.0 * ci * h[2] - wi[2])
        k = 1.0
        if not (wo[2] * wi[2] > 0.0):
            return ZERO3, 1.0, False
    # micro- and macrosurface must agree on the side of each direction (else the BSDF is zero)
    if not (ci * wi[2] > 0.0 and vec.dot(wo, h) * wo[2] > 0.0):
        return ZERO3, 1.0, False
    return wo, k, True


@leaf
def halfvector_copy(wi_b, wo_b, wi_o, eta, transmissive):
    """Shift the outgoing direction at one vertex by copying the half vector (Eq. 15).

    All directions in the vertex's local shading frame, pointing away from it. ``eta`` is the
    material's relative index int/ext (1 for non-dielectrics); ``transmissive`` says whether a
    refraction is possible at all. Returns ``(wo_o, jacobian_solid_angle, ok)``.
    """
    if not (eta > 0.0 and math.isfinite(eta)):
        return ZERO3, 0.0, False            # an invalid material row: fail rather than divide by 0
    refl = wi_b[2] * wo_b[2] > 0.0
    if not refl:
        if not transmissive or wi_o[2] == 0.0:
            return ZERO3, 0.0, False
        if eta == 1.0:                     # index-matched: straight through, no half vector
            return (-wi_o[0], -wi_o[1], -wi_o[2]), 1.0, True
    h, k, ok = half_vector(wi_b, wo_b, eta)
    if not ok:
        return ZERO3, 0.0, False
    wo_o, k_o, ok = outgoing(wi_o, h, eta, not refl)
    if not ok:
        return ZERO3, 0.0, False
    d_b = dh_dwo(wi_b, wo_b, h, k)
    d_o = dh_dwo(wi_o, wo_o, h, k_o)
    if not (d_b > 0.0 and d_o > 0.0):
        return ZERO3, 0.0, False
    j = d_b / d_o
    if not math.isfinite(j):
        return ZERO3, 0.0, False
    return wo_o, j, True


@block
def halfvector_copy_world(ns_b, wi_b, wo_b, ns_o, wi_o, eta, transmissive):
    """:func:`halfvector_copy` with world-space directions; the local frames are
    ``vec.coordinate_system`` of the base and offset shading normals. Returns (wo_o world, J_w, ok)."""
    sb, tb = vec.coordinate_system(ns_b)
    so, to = vec.coordinate_system(ns_o)
    wo, j, ok = halfvector_copy(vec.to_local(wi_b, sb, tb, ns_b), vec.to_local(wo_b, sb, tb, ns_b),
                                vec.to_local(wi_o, so, to, ns_o), eta, transmissive)
    if not ok:
        return ZERO3, 0.0, False
    return vec.normalize(vec.to_world(wo, so, to, ns_o)), j, True


@leaf
def halfvector_copy_mat(mat, wi_b, wo_b, wi_o, is_delta):
    """Half-vector copy at a vertex with material row ``mat`` (local frame). For a delta lobe the
    returned Jacobian is 1: the direction carries a discrete probability, not a density."""
    t = int(mat[L.MAT_TYPE])
    dielectric = t == L.DIELECTRIC or t == L.ROUGHDIELECTRIC
    eta = mat[L.MAT_ETA] if dielectric else 1.0
    if t == L.NULL:
        return (-wi_o[0], -wi_o[1], -wi_o[2]), 1.0, wi_o[2] != 0.0
    wo, j, ok = halfvector_copy(wi_b, wo_b, wi_o, eta, dielectric)
    if ok and is_delta:
        j = 1.0
    return wo, j, ok
