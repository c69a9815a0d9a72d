"""The per-photon loop of a photon-gradient camera pass at a surface gather point, and its plumbing:
GPM's (Hua et al. 2017, Sec. 4) and the surface part of the volumetric full images (G-VPM, G-BRE;
Gruson et al. 2018, Sec. 6: "surface interactions are handled by [Hua et al. 2017]") run the same
loop and differ only in the light half of the photon shift, which the loop receives as two
functions (:func:`make_shift_photons`):

* ``photon_base(sa, lp, v, r, stack) -> state``: what photon row v's shift needs that does not
  depend on the neighbour -- its parent and the parent's value towards the base direction (GPM:
  ``gpm_light.parent_base``), and through media the recorded edge's transmittance -- computed once
  per photon for its four shifts;
* ``shift(sa, lp, mtab, prm, v, state, base, off, r, stack) -> (status, term, ratio)``: the shift to
  one offset gather point ``off`` = (p', ng', frame', wi', mat') from ``base`` = (p, frame): the
  outcome (``RECONNECTED``, ``FAILED``, ``MANIFOLD``), the photon term at the offset
  before the camera weight (f Phi / ``|cos_g|``, :func:`at_offset`), and the MIS density ratio
  p'/p of the light side (the camera side, a replayed path, contributes 1).

The loop sums the pixel's nine buffers (L, D_k, S_k; :mod:`gdlearn.integrators.gradients`) in a row
scratch term by term in photon order and writes them once, and counts the shifts in integers: the
same additions in the same order as a buffer write per term, so the buffers are those of the
straightforward loop bit for bit (tests/test_photon_fast_passes.py) without
a call per term. The MIS weight is Eq. 11 in ratio form, 1 / (1 + r) with r = p' ``|J|`` / p
(:func:`gdlearn.shifts.mis.mis_weight_from_log_ratio`); a failed shift has weight 1 and no offset
(Hua et al. 2017, Sec. 4.3).

numba has no cacheable way to pass a compiled function as an argument (a dispatcher argument makes
the caller uncacheable and the callee recompile in every process), so :func:`make_shift_photons`
builds one loop per shift as a closure over the two functions, which numba compiles as direct,
inlinable calls. The cache finds it again in the next process because ``kernels.jit._ClosureCache``
keys it by those functions' names and code (numba's own key pickled them with a per-process uuid,
and every process compiled the loop anew).
"""
from __future__ import annotations

import math

import numpy as np

from gdlearn.kernels.bsdf.dispatch import bsdf_eval
from gdlearn.kernels.jit import block, inlined
from gdlearn.kernels.vec import dot, to_local
from gdlearn.integrators.photon.gather import _class_ok, parent_ok
from gdlearn.shifts.mis import mis_weight_from_log_ratio

#: outcome counters of the photon shifts (GpmOut.count[:, i]): reconnected, failed, moved by the manifold walk
RECONNECTED, FAILED, MANIFOLD = 0, 1, 2


@block
def put(buf, hh, i, y, x, v, scale):
    """buf[hh, i, y, x] += scale * v (a buffer of :mod:`gdlearn.integrators.gradients`)."""
    for c in range(3):
        buf[hh, i, y, x, c] += scale * v[c]


@inlined
def finite3(v):
    return np.isfinite(v[0]) and np.isfinite(v[1]) and np.isfinite(v[2])


@block
def offset_points():
    """Scratch for the four offset gather points of a base sample: (ok, p, ng, frame, wi, material
    row, camera weight), one row per neighbour k (right, left, down, up)."""
    return (np.zeros(4, dtype=np.bool_), np.zeros((4, 3)), np.zeros((4, 3)), np.zeros((4, 3, 3)), np.zeros((4, 3)),
            np.zeros(4, dtype=np.int64), np.zeros((4, 3)))


@inlined
def store_offset(offs, k, p2, ng2, fr2, wi2, mid2, beta2):
    """Neighbour k's gather point (the replayed camera path reached one of the base's structure)."""
    o_ok, o_p, o_ng, o_fr, o_wi, o_mat, o_beta = offs
    o_ok[k] = True
    for c in range(3):
        o_p[k, c] = p2[c]
        o_ng[k, c] = ng2[c]
        o_wi[k, c] = wi2[c]
        o_beta[k, c] = beta2[c]
        for a in range(3):
            o_fr[k, a, c] = fr2[a][c]
    o_mat[k] = mid2


@inlined
def offset_point(offs, k):
    """Row k of the offset gather points ``offs`` = (ok, p, ng, frame, wi, material row, camera
    weight) as tuples: (p', ng', frame', wi', material row, camera weight)."""
    o_ok, o_p, o_ng, o_fr, o_wi, o_mat, o_beta = offs
    fr = ((o_fr[k, 0, 0], o_fr[k, 0, 1], o_fr[k, 0, 2]), (o_fr[k, 1, 0], o_fr[k, 1, 1], o_fr[k, 1, 2]),
          (o_fr[k, 2, 0], o_fr[k, 2, 1], o_fr[k, 2, 2]))
    return ((o_p[k, 0], o_p[k, 1], o_p[k, 2]), (o_ng[k, 0], o_ng[k, 1], o_ng[k, 2]), fr,
            (o_wi[k, 0], o_wi[k, 1], o_wi[k, 2]), o_mat[k], (o_beta[k, 0], o_beta[k, 1], o_beta[k, 2]))


@inlined
def admitted(lp, v, prm, m, state):
    """Does photon row v complete the gather path (m camera vertices, class state) into a path the
    pass estimates: within the depth limit, of a wanted class, in the gathered parent subset?"""
    if lp.depth[v] + m + 1 > prm.max_depth:
        return False
    if prm.filter_classes and not _class_ok(lp, v, state, prm.mask):
        return False
    return parent_ok(lp, v, prm)


@inlined
def base_term(lp, v, ng, frame, wi, mat, beta):
    """(ok, c_b): photon v's term at the base gather point, camera weight x f x Phi / ``|cos_g|``
    (SPPM's density term, gather.density); not ok for a photon arriving grazing the gather point's
    surface."""
    ns, s, tt = frame
    wo_w = (-lp.d_in[v, 0], -lp.d_in[v, 1], -lp.d_in[v, 2])
    cg = abs(dot(wo_w, ng))
    if not cg > 1e-9:
        return False, (0.0, 0.0, 0.0)
    f = bsdf_eval(mat, wi, to_local(wo_w, s, tt, ns))
    return True, (beta[0] * f[0] * lp.beta[v, 0] / cg, beta[1] * f[1] * lp.beta[v, 1] / cg,
                  beta[2] * f[2] * lp.beta[v, 2] / cg)


@inlined
def at_offset(status, lp, v, ratio3, ratio, w_arr, off):
    """(status, term, ratio): the offset photon, of power beta_v x ratio3 arriving along w_arr, as
    the offset gather point sees it (the base estimate's f Phi / ``|cos_g|``, gather.density)."""
    zero = (0.0, 0.0, 0.0)
    if status == FAILED:
        return FAILED, zero, 0.0
    p2, ng2, frame2, wi2, mat2 = off
    wo_w = (-w_arr[0], -w_arr[1], -w_arr[2])
    cg = abs(dot(wo_w, ng2))
    if not cg > 1e-9:
        return FAILED, zero, 0.0
    ns2, s2, t2 = frame2
    f = bsdf_eval(mat2, wi2, to_local(wo_w, s2, t2, ns2))
    return status, (f[0] * lp.beta[v, 0] * ratio3[0] / cg, f[1] * lp.beta[v, 1] * ratio3[1] / cg,
                    f[2] * lp.beta[v, 2] * ratio3[2] / cg), ratio


@inlined
def _weighted(status, term, beta2, ratio):
    """(status, c_o): the offset term with the offset's camera weight; a non-finite term or density
    ratio fails the shift (weight 1, no offset) rather than reaching an image."""
    if status == FAILED:
        return FAILED, (0.0, 0.0, 0.0)
    c_o = (beta2[0] * term[0], beta2[1] * term[1], beta2[2] * term[2])
    if not (finite3(c_o) and ratio > 0.0 and math.isfinite(ratio)):
        return FAILED, c_o
    return status, c_o


@inlined
def _add_shift(acc, k, status, c_o, c_b, ratio):
    """Neighbour k's terms of one photon into the row scratch: D_k += w (c_o - c_b), S_k += w c_o
    with w Eq. 11's balance weight, or D_k -= c_b for a failed shift (w = 1, Hua et al. Sec. 4.3).
    A pair's two weights sum to 1 within 1e-9 (reconnection, tests/test_gpm.py) and 1e-4 (the
    manifold walk's determinants are central differences, tests/test_gpm_manifold.py)."""
    if status == FAILED:
        for c in range(3):
            acc[1 + k, c] += -1.0 * c_b[c]
        return
    wgt = mis_weight_from_log_ratio(math.log(ratio))
    for c in range(3):
        acc[1 + k, c] += wgt * (c_o[c] - c_b[c])
        acc[5 + k, c] += wgt * c_o[c]


@inlined
def _copy9(dst, src):
    for j in range(9):
        for c in range(3):
            dst[j, c] = src[j, c]


def make_shift_photons(photon_base, shift):
    """The per-photon loop for one photon shift (``photon_base``, ``shift``: the module docstring's
    contract), compiled per shift: ``loop(sa, lp, mtab, prm, out, hh, y, x, gp, r, cand, n, offs,
    acc, stack)`` adds the base gather point ``gp`` = (p, ng, frame, wi, material row, camera weight,
    class, camera vertices)'s photons cand[:n] -- their base terms and their shifts to the offset
    gather points ``offs`` (:func:`offset_point`) -- to half hh of pixel (y, x) of ``out`` (a
    ``gpm_gather.GpmOut``), sets its M, and returns the number of non-finite base terms dropped.
    ``acc`` is a (9, 3) row scratch."""

    @block
    def shift_photons(sa, lp, mtab, prm, out, hh, y, x, gp, r, cand, n, offs, acc, stack):
        p, ng, frame, wi, mid, beta, state, m = gp
        mat = sa.materials[mid]
        o_ok = offs[0]
        nbad = 0
        cnt = 0
        counts = np.zeros(3, dtype=np.int64)
        _copy9(acc, out.phi[hh, :, y, x])
        for i in range(n):
            v = cand[i]
            if not admitted(lp, v, prm, m, state):
                continue
            cnt += 1
            ok, c_b = base_term(lp, v, ng, frame, wi, mat, beta)
            if not ok:
                continue
            if not finite3(c_b):
                nbad += 1
                continue
            for c in range(3):
                acc[0, c] += c_b[c]
            pb = photon_base(sa, lp, v, r, stack)        # the neighbour-free half, once for all four
            for k in range(4):
                status = FAILED
                c_o = (0.0, 0.0, 0.0)
                ratio = 0.0
                if o_ok[k]:
                    p2, ng2, fr2, wi2, mid2, beta2 = offset_point(offs, k)
                    status, term, ratio = shift(sa, lp, mtab, prm, v, pb, (p, frame),
                                                (p2, ng2, fr2, wi2, sa.materials[mid2]), r, stack)
                    status, c_o = _weighted(status, term, beta2, ratio)
                counts[status] += 1
                _add_shift(acc, k, status, c_o, c_b, ratio)
        _copy9(out.phi[hh, :, y, x], acc)
        for st in range(3):
            out.count[hh, st, y, x] += counts[st]
        out.m[hh, y, x] = cnt
        return nbad

    return shift_photons
