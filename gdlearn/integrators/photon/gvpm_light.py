"""Completing the light subpath of a shifted volume photon in G-VPM (Gruson et al. 2018, Sec. 4.3;
PHOTONS.md Sec. 5.4): the reconnection from the photon's parent a = y_{s-1} to the offset photon b'.

The photon shift moved b (a medium vertex) to b' in the same medium with |db'/db| = 1 (Eq. 16: no
projection step, unlike surfaces). The light subpath y_0 .. a is kept and the edge a -> b' replaces
a -> b. In ratio form, with the photon's power beta_b (its light subpath's f / p, the medium's
sigma_s T / pdf of the edge included; :mod:`gdlearn.photons.records`), the offset photon's power is
(Gruson et al. 2018, Eq. 11-12, the light-subpath factor and tau(a, b') G(a, b'))

    beta_b' = beta_b * [f_a(w') / f_a(w)] * [T(l') / T(l)] * (l^2 / l'^2)

with w, w' the directions a -> b, a -> b', l, l' their lengths, f_a the parent's scattering in its
sampling measure (sigma_s-free phase function at a medium vertex, cosine-weighted adjoint BSDF at a
surface, the emission profile at an emitter) and T the edge's transmittance per channel: the offset
contribution f(T x) |dT/dx| / p(x) keeps the base's density p(b | a) = p_w(w) p_l(l) / l^2 (volume
measure, dV = l^2 dw dl). The light side of the MIS ratio (Eq. 19) is the density of b' over b's,

    p(b' | a) / p(b | a) = [p_w(w') / p_w(w)] * [p_l(l') / p_l(l)] * (l^2 / l'^2),

p_l the tracer's collision density (:func:`gdlearn.kernels.media.medium.distance_pdf`, spectral MIS).
Base and offset densities are computed by the same function from positions, so the reverse shift's
ratio is the exact reciprocal and the two MIS weights of a pair sum to one.

Refused (the shift fails: weight 1, no offset): a parent on a specular lobe or a null interface
(the manifold walk is not implemented for volumes yet), a surface parent whose new direction leaves
on the other side of its geometric normal (Sec. 5.11), and an offset edge that meets any surface
before b' -- visibility is tested over the *whole* segment a -> b' (the reference code's test
covers only its first 0.1 %, PHOTONS.md E8). Since the base edge a -> b of a recorded light path
crosses no surface (a null interface would be a vertex of its own), this keeps b' in the photon's
medium and makes the rule symmetric between a shift and its reverse.
"""
from __future__ import annotations

import math

from gdlearn.kernels.accel.bvh import closest_hit_inline
from gdlearn.kernels.geometry import offset_origin
from gdlearn.kernels.jit import block
from gdlearn.kernels.media.medium import distance_pdf, medium_params
from gdlearn.kernels.media.phase import hg_eval
from gdlearn.photons.records import K_MEDIUM
from gdlearn.integrators.photon.gpm_light import _dir, parent_factor

#: reconnect() outcomes
OK, FAIL, FAIL_SPECULAR = 0, 1, 2


@block
def _parent_ratio(sa, lp, q, v, w_new):
    """(status, f_a(w') / f_a(w) per channel, p_w(w') / p_w(w)) of parent row q towards w_new."""
    one = (1.0, 1.0, 1.0)
    if lp.kind[q] == K_MEDIUM:
        g = medium_params(sa.media[lp.obj[q]])[2]
        w_old, _ = _dir((lp.pos[q, 0], lp.pos[q, 1], lp.pos[q, 2]), (lp.pos[v, 0], lp.pos[v, 1], lp.pos[v, 2]))
        wi = (-lp.d_in[q, 0], -lp.d_in[q, 1], -lp.d_in[q, 2])       # Mitsuba's wi: back along the arrival
        fb = hg_eval(g, wi[0] * w_old[0] + wi[1] * w_old[1] + wi[2] * w_old[2])
        fo = hg_eval(g, wi[0] * w_new[0] + wi[1] * w_new[1] + wi[2] * w_new[2])
        if not (fb > 0.0 and fo > 0.0):
            return FAIL, one, 0.0
        r = fo / fb                   # HG is sampled exactly: the pdf ratio is the value ratio
        return OK, (r, r, r), r
    status, fr, pr = parent_factor(sa, lp, q, v, w_new)
    if status == 2:
        return FAIL_SPECULAR, one, 0.0
    if status != 0:
        return FAIL, one, 0.0
    return OK, fr, pr


@block
def reconnect(sa, lp, v, b_off, stack):
    """Reconnect photon row v's parent to the offset photon ``b_off`` (module docstring). Returns
    (status, beta_b' / beta_b per channel, light-side density ratio p(b' | a) / p(b | a), the
    direction a -> b' the offset photon arrives along)."""
    zero = (0.0, 0.0, 0.0)
    q = lp.parent[v]
    if q < 0:
        return FAIL, zero, 0.0, zero
    a = (lp.pos[q, 0], lp.pos[q, 1], lp.pos[q, 2])
    w_new, l_new = _dir(a, b_off)
    _, l_old = _dir(a, (lp.pos[v, 0], lp.pos[v, 1], lp.pos[v, 2]))
    if not (l_new > 0.0 and l_old > 0.0):
        return FAIL, zero, 0.0, zero
    status, fr, pr = _parent_ratio(sa, lp, q, v, w_new)
    if status != OK:
        return status, zero, 0.0, zero
    o = a if lp.kind[q] == K_MEDIUM else offset_origin(a, (lp.nrm[q, 0], lp.nrm[q, 1], lp.nrm[q, 2]), w_new)
    t, prim, _, _ = closest_hit_inline(sa.nodes, sa.node_info, sa.prims, sa.prim_info, o, w_new, 0.0, math.inf,
                                       stack)
    reach = math.sqrt((b_off[0] - o[0]) ** 2 + (b_off[1] - o[1]) ** 2 + (b_off[2] - o[2]) ** 2)
    if prim >= 0 and t <= reach:       # the whole segment a -> b' (E8), not its first 0.1 %
        return FAIL, zero, 0.0, zero
    sig = medium_params(sa.media[lp.medium[v]])[0]
    p_old = distance_pdf(sig, l_old)
    p_new = distance_pdf(sig, l_new)
    if not (p_old > 0.0 and p_new > 0.0):
        return FAIL, zero, 0.0, zero
    geo = (l_old * l_old) / (l_new * l_new)
    dl = l_new - l_old
    # T(l') / T(l) = exp(-sigma (l' - l)) per channel: one exponential, no 0 / 0 in a dense medium
    f3 = (fr[0] * math.exp(-sig[0] * dl) * geo, fr[1] * math.exp(-sig[1] * dl) * geo,
          fr[2] * math.exp(-sig[2] * dl) * geo)
    return OK, f3, pr * (p_new / p_old) * geo, w_new
