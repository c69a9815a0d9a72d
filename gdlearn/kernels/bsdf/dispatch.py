"""BSDF dispatch: sample / eval / pdf of every supported Mitsuba 3 BSDF from one material row.

Conventions (Mitsuba 3's ``BSDF`` interface, ``include/mitsuba/render/bsdf.h``):

* every direction is in the local shading frame (normal = +z) and points AWAY from the surface;
  ``wi`` towards where the path came from (Mitsuba's ``si.wi``), ``wo`` the sampled / queried one;
* ``bsdf_eval`` returns f(wi, wo) |cos theta_o| (non-delta lobes only), ``bsdf_pdf`` the solid-angle
  density of ``bsdf_sample`` for the non-delta lobes, lobe-selection probability included;
* ``bsdf_sample`` returns ``(wo, weight, pdf, is_delta)`` with weight = f |cos wo| / pdf; for a delta
  lobe pdf is the discrete probability of having chosen it and is_delta is True. An invalid sample
  has weight (0, 0, 0) and pdf 0.
* ``twosided`` (Mitsuba's adapter with the same BSDF on both sides) mirrors wi and wo to the front
  when wi.z < 0; without it diffuse, conductors and plastics are black from the back (wi.z <= 0).
  Dielectrics are two-sided by nature; ``null`` is an index-matched pass-through the tracer skips.

The per-type kernels live in bsdf_diffuse / bsdf_conductor / bsdf_dielectric / bsdf_plastic.

**Compiling only the families a scene has**: the material table's tier
(:mod:`gdlearn.kernels.bsdf.tiers`). The ``_front`` stubs below and the rough plastic's class
helpers are typed by ``overload`` with the body of the row's tier, so the lean, smooth and glossy
kernels never type the families they cannot meet. The smooth families add delta lobes only, which
``bsdf_eval`` and ``bsdf_pdf`` do not see: their bodies are the lean ones.
"""
import math

import numpy as np
from numba.extending import overload


from gdlearn.kernels import layout as L
from gdlearn.kernels.bsdf.conductor import (conductor_sample, roughconductor_eval, roughconductor_pdf,
                                            roughconductor_sample)
from gdlearn.kernels.bsdf.dielectric import (dielectric_sample, roughdielectric_eval, roughdielectric_pdf,
                                             roughdielectric_sample)
from gdlearn.kernels.bsdf.diffuse import diffuse_eval, diffuse_pdf, diffuse_sample
from gdlearn.kernels.bsdf.plastic import (ROUGHPLASTIC_WIDTH, plastic_eval, plastic_pdf, plastic_sample,
                                          prepare_plastic, roughplastic_coat_fraction, roughplastic_eval,
                                          roughplastic_eval_pdf, roughplastic_pdf, roughplastic_sample,
                                          roughplastic_spec_prob)
from gdlearn.kernels.jit import INLINED_OPTIONS, block, inlined
from gdlearn.kernels.bsdf.tiers import tier_of

ZERO3 = (0.0, 0.0, 0.0)


@inlined
def _flips(mat, wi):
    """True when Mitsuba's twosided adapter mirrors the query to the front side."""
    t = int(mat[L.MAT_TYPE])
    return (mat[L.MAT_TWOSIDED] != 0.0 and wi[2] < 0.0 and t != L.DIELECTRIC
            and t != L.ROUGHDIELECTRIC and t != L.NULL)


def _compiled_only(*args):
    raise NotImplementedError("compiled code only: call bsdf_sample / bsdf_eval / bsdf_pdf")


def _sample_lean(mat, wi, u_lobe, u1, u2):
    t = int(mat[L.MAT_TYPE])
    if t == L.DIFFUSE:
        return diffuse_sample(mat, wi, u1, u2)
    if t == L.NULL:
        return (-wi[0], -wi[1], -wi[2]), (1.0, 1.0, 1.0), 1.0, True
    return ZERO3, ZERO3, 0.0, False


def _sample_smooth(mat, wi, u_lobe, u1, u2):
    t = int(mat[L.MAT_TYPE])
    if t == L.DIFFUSE:
        return diffuse_sample(mat, wi, u1, u2)
    if t == L.CONDUCTOR:
        return conductor_sample(mat, wi)
    if t == L.DIELECTRIC:
        return dielectric_sample(mat, wi, u_lobe)
    if t == L.NULL:      # pass straight through with probability 1 (the tracer normally skips it)
        return (-wi[0], -wi[1], -wi[2]), (1.0, 1.0, 1.0), 1.0, True
    return ZERO3, ZERO3, 0.0, False


#: the smooth body as a function compiled code can call (the full body ends in it)
_sample_smooth_inlined = inlined(_sample_smooth)


def _sample_glossy(mat, wi, u_lobe, u1, u2):
    t = int(mat[L.MAT_TYPE])
    if t == L.DIFFUSE:
        return diffuse_sample(mat, wi, u1, u2)
    if t == L.ROUGHCONDUCTOR:
        return roughconductor_sample(mat, wi, u1, u2)
    if t == L.ROUGHPLASTIC:
        return roughplastic_sample(mat, wi, u_lobe, u1, u2)
    if t == L.NULL:
        return (-wi[0], -wi[1], -wi[2]), (1.0, 1.0, 1.0), 1.0, True
    return ZERO3, ZERO3, 0.0, False


def _sample_front_all(mat, wi, u_lobe, u1, u2):
    t = int(mat[L.MAT_TYPE])
    if t == L.ROUGHCONDUCTOR:
        return roughconductor_sample(mat, wi, u1, u2)
    if t == L.ROUGHDIELECTRIC:
        return roughdielectric_sample(mat, wi, u_lobe, u1, u2)
    if t == L.PLASTIC:
        return plastic_sample(mat, wi, u_lobe, u1, u2)
    if t == L.ROUGHPLASTIC:
        return roughplastic_sample(mat, wi, u_lobe, u1, u2)
    return _sample_smooth_inlined(mat, wi, u_lobe, u1, u2)


def _sample_front(mat, wi, u_lobe, u1, u2):
    _compiled_only()


@overload(_sample_front, jit_options=INLINED_OPTIONS)
def _sample_front_typed(mat, wi, u_lobe, u1, u2):
    return {"lean": _sample_lean, "smooth": _sample_smooth, "glossy": _sample_glossy,
            "all": _sample_front_all}[tier_of(mat)]


@inlined
def bsdf_sample(mat, wi, u_lobe, u1, u2):
    """Sample wo: ``(wo, weight, pdf, is_delta)``; u_lobe picks the lobe, (u1, u2) the direction.
    A non-finite weight or pdf (never observed; a last guard so NaN cannot reach an image) is
    returned as an invalid sample."""
    flip = _flips(mat, wi)
    wi_f = (wi[0], wi[1], -wi[2]) if flip else wi
    wo, w, pdf, delta = _sample_front(mat, wi_f, u_lobe, u1, u2)
    if not (pdf > 0.0 and pdf < math.inf and abs(w[0] + w[1] + w[2]) < math.inf):
        return ZERO3, ZERO3, 0.0, delta
    if flip:
        return (wo[0], wo[1], -wo[2]), w, pdf, delta
    return wo, w, pdf, delta


def _eval_lean(mat, wi, wo):
    if int(mat[L.MAT_TYPE]) == L.DIFFUSE:
        return diffuse_eval(mat, wi, wo)
    return ZERO3


def _eval_glossy(mat, wi, wo):
    t = int(mat[L.MAT_TYPE])
    if t == L.DIFFUSE:
        return diffuse_eval(mat, wi, wo)
    if t == L.ROUGHCONDUCTOR:
        return roughconductor_eval(mat, wi, wo)
    if t == L.ROUGHPLASTIC:
        return roughplastic_eval(mat, wi, wo)
    return ZERO3


#: the glossy body as a function compiled code can call (the full body ends in it)
_eval_glossy_inlined = inlined(_eval_glossy)


def _eval_front_all(mat, wi, wo):
    t = int(mat[L.MAT_TYPE])
    if t == L.ROUGHDIELECTRIC:
        return roughdielectric_eval(mat, wi, wo)
    if t == L.PLASTIC:
        return plastic_eval(mat, wi, wo)
    return _eval_glossy_inlined(mat, wi, wo)     # conductor, dielectric, null: zero (delta lobes only)


def _eval_front(mat, wi, wo):
    _compiled_only()


@overload(_eval_front, jit_options=INLINED_OPTIONS)
def _eval_front_typed(mat, wi, wo):
    return {"lean": _eval_lean, "smooth": _eval_lean, "glossy": _eval_glossy, "all": _eval_front_all}[tier_of(mat)]


@inlined
def bsdf_eval(mat, wi, wo):
    """f(wi, wo) |cos wo| of the non-delta lobes, an RGB 3-tuple."""
    if _flips(mat, wi):
        return _eval_front(mat, (wi[0], wi[1], -wi[2]), (wo[0], wo[1], -wo[2]))
    return _eval_front(mat, wi, wo)


def _pdf_lean(mat, wi, wo):
    if int(mat[L.MAT_TYPE]) == L.DIFFUSE:
        return diffuse_pdf(mat, wi, wo)
    return 0.0


def _pdf_glossy(mat, wi, wo):
    t = int(mat[L.MAT_TYPE])
    if t == L.DIFFUSE:
        return diffuse_pdf(mat, wi, wo)
    if t == L.ROUGHCONDUCTOR:
        return roughconductor_pdf(mat, wi, wo)
    if t == L.ROUGHPLASTIC:
        return roughplastic_pdf(mat, wi, wo)
    return 0.0


_pdf_glossy_inlined = inlined(_pdf_glossy)


def _pdf_front_all(mat, wi, wo):
    t = int(mat[L.MAT_TYPE])
    if t == L.ROUGHDIELECTRIC:
        return roughdielectric_pdf(mat, wi, wo)
    if t == L.PLASTIC:
        return plastic_pdf(mat, wi, wo)
    return _pdf_glossy_inlined(mat, wi, wo)


def _pdf_front(mat, wi, wo):
    _compiled_only()


@overload(_pdf_front, jit_options=INLINED_OPTIONS)
def _pdf_front_typed(mat, wi, wo):
    return {"lean": _pdf_lean, "smooth": _pdf_lean, "glossy": _pdf_glossy, "all": _pdf_front_all}[tier_of(mat)]


@inlined
def bsdf_pdf(mat, wi, wo):
    """Solid-angle density with which :func:`bsdf_sample` produces wo (non-delta lobes)."""
    if _flips(mat, wi):
        return _pdf_front(mat, (wi[0], wi[1], -wi[2]), (wo[0], wo[1], -wo[2]))
    return _pdf_front(mat, wi, wo)


def _eval_pdf_lean(mat, wi, wo):
    if int(mat[L.MAT_TYPE]) == L.DIFFUSE:
        return diffuse_eval(mat, wi, wo), diffuse_pdf(mat, wi, wo)
    return ZERO3, 0.0


def _eval_pdf_glossy(mat, wi, wo):
    # each family by name (not through the glossy eval and pdf bodies): those would type the rough
    # plastic's separate eval and pdf too, two more functions to compile
    t = int(mat[L.MAT_TYPE])
    if t == L.DIFFUSE:
        return diffuse_eval(mat, wi, wo), diffuse_pdf(mat, wi, wo)
    if t == L.ROUGHCONDUCTOR:
        return roughconductor_eval(mat, wi, wo), roughconductor_pdf(mat, wi, wo)
    if t == L.ROUGHPLASTIC:
        return roughplastic_eval_pdf(mat, wi, wo)
    return ZERO3, 0.0


_eval_pdf_glossy_inlined = inlined(_eval_pdf_glossy)


def _eval_pdf_front_all(mat, wi, wo):
    t = int(mat[L.MAT_TYPE])
    if t == L.ROUGHDIELECTRIC:
        return roughdielectric_eval(mat, wi, wo), roughdielectric_pdf(mat, wi, wo)
    if t == L.PLASTIC:
        return plastic_eval(mat, wi, wo), plastic_pdf(mat, wi, wo)
    return _eval_pdf_glossy_inlined(mat, wi, wo)


def _eval_pdf_front(mat, wi, wo):
    _compiled_only()


@overload(_eval_pdf_front, jit_options=INLINED_OPTIONS)
def _eval_pdf_front_typed(mat, wi, wo):
    return {"lean": _eval_pdf_lean, "smooth": _eval_pdf_lean, "glossy": _eval_pdf_glossy,
            "all": _eval_pdf_front_all}[tier_of(mat)]


@inlined
def bsdf_eval_pdf(mat, wi, wo):
    """(:func:`bsdf_eval`, :func:`bsdf_pdf`) at once, the same values: where a caller needs both (a
    next-event estimate and its MIS weight), a rough plastic computes the terms they share once."""
    if _flips(mat, wi):
        return _eval_pdf_front(mat, (wi[0], wi[1], -wi[2]), (wo[0], wo[1], -wo[2]))
    return _eval_pdf_front(mat, wi, wo)


@inlined
def bsdf_is_null(mat):
    return int(mat[L.MAT_TYPE]) == L.NULL


@inlined
def bsdf_is_delta_only(mat):
    """True when every lobe is a Dirac delta (NEE / eval are useless there)."""
    t = int(mat[L.MAT_TYPE])
    return t == L.CONDUCTOR or t == L.DIELECTRIC or t == L.NULL


@inlined
def bsdf_has_delta(mat):
    t = int(mat[L.MAT_TYPE])
    return t == L.CONDUCTOR or t == L.DIELECTRIC or t == L.PLASTIC or t == L.NULL


@inlined
def bsdf_eta(mat, wi, wo):
    """Relative IOR crossed from wi's side to wo's side (Mitsuba's ``bs.eta``): eta_it on refraction
    through a dielectric, 1 otherwise. The path tracer's Russian roulette uses throughput * eta^2."""
    t = int(mat[L.MAT_TYPE])
    if (t == L.DIELECTRIC or t == L.ROUGHDIELECTRIC) and wi[2] * wo[2] < 0.0:
        eta = mat[L.MAT_ETA]
        return eta if wi[2] > 0.0 else 1.0 / eta
    return 1.0


# an overload must return a Python function, not a compiled one: these wrap the rough plastic's
# compiled helpers
def _spec_prob_all(mat, cos_i):
    return roughplastic_spec_prob(mat, cos_i)


def _coat_fraction_all(mat, wi, wo):
    return roughplastic_coat_fraction(mat, wi, wo)


# a lean or smooth tier has no rough plastic: its callers never reach these there
def _no_spec_prob(mat, cos_i):
    return 0.0


def _no_coat_fraction(mat, wi, wo):
    return 0.0


def _spec_prob_tiered(mat, cos_i):
    _compiled_only()


@overload(_spec_prob_tiered, jit_options=INLINED_OPTIONS)
def _spec_prob_typed(mat, cos_i):
    """:func:`roughplastic_spec_prob` where the tier has rough plastics (its callers test the type
    first), typed for the other tiers without the plastic's tables."""
    return _spec_prob_all if tier_of(mat) in ("glossy", "all") else _no_spec_prob


def _coat_fraction_tiered(mat, wi, wo):
    _compiled_only()


@overload(_coat_fraction_tiered, jit_options=INLINED_OPTIONS)
def _coat_fraction_typed(mat, wi, wo):
    """As :func:`_spec_prob_typed`, for :func:`roughplastic_coat_fraction`."""
    return _coat_fraction_all if tier_of(mat) in ("glossy", "all") else _no_coat_fraction


@block
def vertex_class(mat, threshold):
    """How a path vertex on this material scatters, for shift mappings and effect classification.

    diffuse -> V_DIFFUSE; conductor / dielectric / null -> V_SPECULAR; rough conductor / dielectric
    -> V_GLOSSY if alpha >= threshold else V_SPECULAR. Plastics -> V_DIFFUSE: their diffuse base is
    always present and connectable (a smooth plastic's delta lobe is told apart per sample by
    :func:`lobe_class`; a rough plastic's lobes are both non-delta and evaluated together).
    """
    t = int(mat[L.MAT_TYPE])
    if t == L.DIFFUSE or t == L.PLASTIC or t == L.ROUGHPLASTIC:
        return L.V_DIFFUSE
    if t == L.ROUGHCONDUCTOR or t == L.ROUGHDIELECTRIC:
        return L.V_GLOSSY if mat[L.MAT_ALPHA] >= threshold else L.V_SPECULAR
    return L.V_SPECULAR


@block
def lobe_class(mat, is_delta, threshold):
    """Class of the lobe a bsdf_sample actually used: V_SPECULAR for a delta sample, else
    :func:`vertex_class` (so a smooth plastic is V_SPECULAR on its coating, V_DIFFUSE below)."""
    if is_delta:
        return L.V_SPECULAR
    return vertex_class(mat, threshold)


@block
def sampled_lobe_class(mat, wi, u_lobe, is_delta, threshold):
    """Like :func:`lobe_class` but also resolves a rough plastic, whose two lobes are both non-delta:
    the lobe bsdf_sample picked for this (wi, u_lobe) -- the microfacet coating (V_GLOSSY, or
    V_SPECULAR below the threshold) or the diffuse base (V_DIFFUSE). Matches the effects plan, which
    lets a roughplastic produce both kinds of vertices."""
    if int(mat[L.MAT_TYPE]) != L.ROUGHPLASTIC or is_delta:
        return lobe_class(mat, is_delta, threshold)
    cos_i = -wi[2] if _flips(mat, wi) else wi[2]
    if cos_i <= 0.0:
        return L.V_DIFFUSE
    if u_lobe < _spec_prob_tiered(mat, cos_i):
        return L.V_GLOSSY if mat[L.MAT_ALPHA] >= threshold else L.V_SPECULAR
    return L.V_DIFFUSE


@block
def nee_classes(mat, threshold):
    """(class of the coating part, class of the rest) of a next-event term at this material.

    Only a rough plastic has two non-delta lobes of different classes (coating V_GLOSSY, or
    V_SPECULAR below the threshold, over a V_DIFFUSE base); every other material returns its
    :func:`vertex_class` twice. See :func:`nee_class_share`."""
    c = vertex_class(mat, threshold)
    if int(mat[L.MAT_TYPE]) != L.ROUGHPLASTIC:
        return c, c
    return (L.V_GLOSSY if mat[L.MAT_ALPHA] >= threshold else L.V_SPECULAR), c


@block
def nee_class_share(mat, wi, wo, want_coat, want_rest):
    """The share of a next-event term f(wi, wo) that belongs to the wanted effect classes.

    ``want_coat`` / ``want_rest``: does the effects mask keep the path when this vertex is of the
    first / second class of :func:`nee_classes`? A rough plastic's term is split by
    :func:`bsdf_plastic.roughplastic_coat_fraction`, the partition :func:`sampled_lobe_class`
    realises for BSDF samples (so NEE and BSDF sampling, MIS-combined, estimate the same per-class
    image and the per-effect images still sum to the full one). 1 or 0 for every other material."""
    if want_coat and want_rest:
        return 1.0
    if not (want_coat or want_rest):
        return 0.0
    if int(mat[L.MAT_TYPE]) != L.ROUGHPLASTIC:
        return 1.0                      # one class: both flags are equal, so this is unreachable
    if _flips(mat, wi):
        wi, wo = (wi[0], wi[1], -wi[2]), (wo[0], wo[1], -wo[2])
    k = _coat_fraction_tiered(mat, wi, wo)
    return k if want_coat else 1.0 - k


@block
def lobe_class_ratio(mat_b, wi_b, wo_b, cls_b, mat_o, wi_o, wo_o, threshold):
    """``(ratio, ok)`` for an offset vertex that continues the base's BSDF-sampled lobe class ``cls_b``
    (a shift's effect-class label), when the effects mask is restricted.

    A rough plastic's sampled lobe is a draw of the posterior P_x(c) = :func:`nee_class_share`'s coat
    fraction at the base's (wi_b, wo_b). An offset on a rough plastic keeps the base's label and weighs
    P_y(c) / P_x(c) at its own (wi_o, wo_o): its expected class-c contribution is then
    sum_c P_x(c) f(y) P_y(c) / P_x(c) = f(y) P_y(c), the offset path's own share, as the primal
    estimator of its pixel splits it. Both vertices must be rough plastics with the same class pair;
    when only one is (or the pairs differ) the label of one side cannot stand for the other's split,
    so the shift fails (``ok`` False: a symmetric rule, the reverse shift fails as well, so the MIS
    weights stay complementary). Any other pair: (1, True), the single class is exact."""
    rp_b = int(mat_b[L.MAT_TYPE]) == L.ROUGHPLASTIC
    rp_o = int(mat_o[L.MAT_TYPE]) == L.ROUGHPLASTIC
    if not (rp_b or rp_o):
        return 1.0, True
    if not (rp_b and rp_o) or nee_classes(mat_b, threshold) != nee_classes(mat_o, threshold):
        return 0.0, False
    coat = cls_b != L.V_DIFFUSE
    p_b = nee_class_share(mat_b, wi_b, wo_b, coat, not coat)
    p_o = nee_class_share(mat_o, wi_o, wo_o, coat, not coat)
    if not p_b > 0.0:
        return 0.0, False
    return p_o / p_b, True


# --- building rows (Python, once per material) -----------------------------------------------------
def prepare_material_row(row: np.ndarray) -> np.ndarray:
    """Fill the precomputed MAT_AUX columns of a material row in place (plastics' internal Fresnel
    reflectance, specular sampling weight and rough transmittance table). Returns the row."""
    t = int(row[L.MAT_TYPE])
    if t == L.PLASTIC or t == L.ROUGHPLASTIC:
        prepare_plastic(row)
    return row


def material_row(bsdf, width: int | None = None) -> np.ndarray:
    """The float64 material row of a :class:`gdlearn.scene.model.BSDF` (columns layout.MAT_*).

    ``width`` defaults to layout.MAT_WIDTH. A roughplastic needs ``bsdf_plastic.ROUGHPLASTIC_WIDTH``
    columns for its transmittance table and raises ValueError (naming the fix) if the row is narrower.
    """
    if bsdf.type not in L.BSDF_TYPES:
        raise ValueError(f"unknown BSDF type {bsdf.type!r}; fix: use one of {sorted(L.BSDF_TYPES)}")
    t = L.BSDF_TYPES[bsdf.type]
    if width is None:
        width = L.MAT_WIDTH
    if t == L.ROUGHPLASTIC and width < ROUGHPLASTIC_WIDTH:
        raise ValueError(f"roughplastic needs a material row of {ROUGHPLASTIC_WIDTH} columns (its "
                         f"64-entry transmittance table) but layout.MAT_WIDTH is {width}; fix: raise "
                         f"layout.MAT_WIDTH to >= {ROUGHPLASTIC_WIDTH}")
    row = np.zeros(width, dtype=np.float64)
    row[L.MAT_TYPE] = t
    row[L.MAT_TWOSIDED] = 1.0 if bsdf.twosided else 0.0
    row[L.MAT_R:L.MAT_R + 3] = np.asarray(bsdf.reflectance, dtype=np.float64).reshape(3)
    row[L.MAT_SR:L.MAT_SR + 3] = np.asarray(bsdf.specular_reflectance, dtype=np.float64).reshape(3)
    row[L.MAT_ST:L.MAT_ST + 3] = np.asarray(bsdf.specular_transmittance, dtype=np.float64).reshape(3)
    row[L.MAT_ALPHA] = max(float(bsdf.alpha), 1e-4)     # Mitsuba clamps alpha to 1e-4 as well
    dist = str(bsdf.distribution).lower()
    if dist not in ("beckmann", "ggx"):
        raise ValueError(f"unknown microfacet distribution {bsdf.distribution!r}; fix: beckmann or ggx")
    row[L.MAT_DIST] = L.GGX if dist == "ggx" else L.BECKMANN
    if not (bsdf.int_ior > 0 and bsdf.ext_ior > 0):
        raise ValueError(f"int_ior / ext_ior must be > 0 (got {bsdf.int_ior}, {bsdf.ext_ior}); fix: "
                         "use positive indices of refraction")
    if t in (L.ROUGHDIELECTRIC, L.ROUGHPLASTIC) and bsdf.int_ior == bsdf.ext_ior:
        # as Mitsuba 3: an index-matched rough interface maps every microfacet to the same refracted
        # direction (a delta hidden in a "rough" lobe, infinite pdf)
        raise ValueError(f"{bsdf.type} needs int_ior != ext_ior (both {bsdf.int_ior}); fix: use "
                         "'dielectric' / 'plastic' for an index-matched interface, or change an ior")
    row[L.MAT_ETA] = float(bsdf.int_ior) / float(bsdf.ext_ior)
    row[L.MAT_NONLINEAR] = 1.0 if bsdf.nonlinear else 0.0
    return prepare_material_row(row)
