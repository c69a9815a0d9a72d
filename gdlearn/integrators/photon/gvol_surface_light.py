"""The light half of a surface photon's shift in a scene with media: GPM's hybrid shift (Hua et al.
2017, Sec. 4.2, Eq. 5-6; PHOTONS.md Sec. 2.5) whose photon edge may run through participating media
and null interfaces, and whose parent may be a medium vertex (Gruson et al. 2018, Sec. 4.3 and 6:
the surface part of a full image keeps GPM's shifts).

The offset photon y'_s is GPM's: y* = Eq. 5's rigid copy of y_s into the offset gather point's frame,
projected from the photon's parent a = y_{s-1} (Eq. 6) -- the first surface other than a null
interface on the ray a -> y*, so the projection walks through a medium's index-matched boundary as
the light tracer did (:func:`walk_to_surface`). The parent is the nearest ancestor that is not a null
interface (``gdlearn.integrators.photon.gvpm_light._ancestor``), and it is re-evaluated towards
the new direction by :func:`gdlearn.integrators.photon.gvpm_light.parent_base_vol` and
:func:`~gdlearn.integrators.photon.gvpm_light.parent_offset_vol`: the phase function at a medium
vertex (HG is sampled exactly: value ratio = density ratio), GPM's
:func:`gdlearn.integrators.photon.gpm_light.parent_base` / ``parent_offset`` at a surface or an
emitter. The camera pass runs GPM's photon loop (:mod:`gdlearn.integrators.photon.photon_shift_loop`)
with :func:`photon_base` -- the parent, its base half and the recorded edge's media, once per photon
-- and :func:`shift_from_base` per neighbour. In ratio form,
with beta the photon's power (its light subpath's f / p, the edge's T / P(pass) included;
:mod:`gdlearn.photons.records`):

    beta'_s = beta_s [f_a(w') / f_a(w)] [T(a, y'_s) / T(a, y_s)] G*                   (power)
    p'/p    =        [p_a(w') / p_a(w)] [P(a, y'_s) / P(a, y_s)] G*                    (MIS, Eq. 11)

G* = (``|cos*|`` / d*^2) / (``|cos_s|`` / d^2) the geometry-times-Jacobian factor of GPM
(:func:`gdlearn.shifts.photon.photon_geometry_ratio`: G(a, y') ``|dy'/dy|`` / G(a, y), Eq. 6), T the
transmittance of the edge per channel and P the tracer's probability of passing it without a
collision (spectral MIS, :func:`gdlearn.kernels.media.medium.pass_probability`), each the product
over the edge's media segments. In vacuum both media factors are 1 and this is GPM's shift exactly.

A parent on a specular chain goes to GPM's manifold walk (Eq. 7-8) only when the chain and the photon
edge lie in vacuum (the walk has no transmittance); otherwise the shift fails (weight 1, unbiased).
Refused as well, symmetrically: an offset edge that crosses another number of null interfaces or
arrives through another medium than the base edge, a projection onto a specular surface or outside
the offset gather point's kernel (PHOTONS.md Sec. 2.6), and an offset photon whose inverse shift
does not return y_s (Hua et al. 2017, Sec. 4.3; GPM's ``_reversible``).
"""
from __future__ import annotations

import math

from gdlearn.kernels import layout as L
from gdlearn.kernels.accel.bvh import closest_hit_inline
from gdlearn.kernels.bsdf.dispatch import bsdf_is_null, vertex_class
from gdlearn.kernels.geometry import INFO_MAT, offset_origin, surface
from gdlearn.kernels.jit import block, inlined
from gdlearn.kernels.media.boundary import next_medium
from gdlearn.kernels.media.medium import medium_params, pass_probability
from gdlearn.photons.records import K_SURFACE
from gdlearn.integrators.photon.gather import specular_vertex
from gdlearn.integrators.photon.gpm_light import P_FAIL, P_SPECULAR, _dir, same_point
from gdlearn.integrators.photon.gvpm_light import FAIL, FAIL_SPECULAR, MAX_CROSSINGS, OK, _ancestor, _spawn, \
    parent_base_vol, parent_offset_vol
from gdlearn.integrators.photon.photon_manifold import manifold_photon
from gdlearn.integrators.photon.photon_shift_loop import FAILED, MANIFOLD, RECONNECTED, at_offset
from gdlearn.shifts.photon import offset_target, photon_geometry_ratio, rotate

_ZERO = (0.0, 0.0, 0.0)


@block
def _segment(sa, medium, a, b, tau, logp):
    """Add the straight segment a -> b in ``medium`` (-1: vacuum) to the optical depth and the log
    pass probability; (ok, tau, logp) -- not ok if the tracer could not have passed it."""
    if medium < 0:
        return True, tau, logp
    ln = math.sqrt((b[0] - a[0]) ** 2 + (b[1] - a[1]) ** 2 + (b[2] - a[2]) ** 2)
    sig = medium_params(sa.media[medium])[0]
    pp = pass_probability(sig, ln)
    if not pp > 0.0:
        return False, tau, logp
    return True, (tau[0] + sig[0] * ln, tau[1] + sig[1] * ln, tau[2] + sig[2] * ln), logp + math.log(pp)


@block
def _on_line(a, w, p, ng):
    """The hit p moved onto the line a + t w within its tangent plane. A ray spawned off a surface
    starts ~1e-7 beside a (geometry.offset_origin), so its hit is that far off the line from the
    vertex; on the line, the offset photon y' of a shift through y* is y* itself to rounding (planes;
    O(1e-14) on curved shapes) and the reverse shift's ratios are the exact reciprocals (T4)."""
    den = w[0] * ng[0] + w[1] * ng[1] + w[2] * ng[2]
    if not abs(den) > 1e-12:
        return p
    t = ((p[0] - a[0]) * ng[0] + (p[1] - a[1]) * ng[1] + (p[2] - a[2]) * ng[2]) / den
    return (a[0] + t * w[0], a[1] + t * w[1], a[2] + t * w[2])


@block
def walk_to_surface(sa, a, o, w, medium, stack):
    """From the vertex ``a`` (rays spawned at ``o``) along ``w``, starting in ``medium``: through null
    interfaces (the medium changes at each, Mitsuba's rule) to the first other surface. Lengths are
    measured from ``a`` itself, as the analytic base edge is, so a shift's and its reverse's ratios
    are exact reciprocals. Returns (ok, hit point, geometric normal, prim, null crossings, optical
    depth per channel, log pass probability, the medium the hit is reached through)."""
    tau = _ZERO
    logp = 0.0
    prev = a
    for n in range(MAX_CROSSINGS + 1):
        t, prim, uu, vv = closest_hit_inline(sa.nodes, sa.node_info, sa.prims, sa.prim_info, o, w, 0.0, math.inf,
                                             stack)
        if prim < 0:
            break
        p, ng, _ = surface(sa.prims, sa.prim_info, prim, o, w, t, uu, vv)
        p = _on_line(a, w, p, ng)
        ok, tau, logp = _segment(sa, medium, prev, p, tau, logp)
        if not ok:
            break
        if not bsdf_is_null(sa.materials[sa.prim_info[prim, INFO_MAT]]):
            return True, p, ng, prim, n, tau, logp, medium
        medium = next_medium(sa.prim_info, prim, medium, w, ng)
        o = offset_origin(p, ng, w)
        prev = p
    return False, a, a, -1, 0, tau, 0.0, medium


@block
def _vacuum_chain(lp, v):
    """Do photon row v's edge and the specular chain above it (up to the last non-specular vertex)
    lie in vacuum? (The manifold walk carries no transmittance.)"""
    u = v
    while True:
        if lp.medium[u] >= 0:
            return False
        q = lp.parent[u]
        if q < 0 or not (lp.kind[q] == K_SURFACE and specular_vertex(lp, q)):
            return True
        u = q


@block
def _base_edge(sa, lp, q, child, n_null, v, r, stack):
    """(ok, tau, log P) of the recorded edge a -> y_s: analytic without null crossings, else walked."""
    a = (lp.pos[q, 0], lp.pos[q, 1], lp.pos[q, 2])
    ys = (lp.pos[v, 0], lp.pos[v, 1], lp.pos[v, 2])
    if n_null == 0:
        return _segment(sa, lp.medium[v], a, ys, _ZERO, 0.0)
    w, _ = _dir(a, ys)
    ok, yb, _, _, n_b, tau, logp, med = walk_to_surface(sa, a, _spawn(lp, q, a, w), w, lp.medium[child], stack)
    return ok and n_b == n_null and med == lp.medium[v] and same_point(yb, ys, a, r), tau, logp


@block
def _reversible(sa, lp, q, child, ys, yh, ystar, p, frame, p2, frame2, r, stack):
    """Does the inverse shift (Eq. 5 from the offset gather point back, projected from a) return y_s?
    Exact when the projection did not move y* (GPM's ``_reversible``, through null interfaces)."""
    yq = (lp.pos[q, 0], lp.pos[q, 1], lp.pos[q, 2])
    if same_point(yh, ystar, yq, r):
        return True
    w, dl = _dir(yq, offset_target(yh, p2, frame2, p, frame))
    if not dl > 0.0:
        return False
    ok, yb, _, _, _, _, _, _ = walk_to_surface(sa, yq, _spawn(lp, q, yq, w), w, lp.medium[child], stack)
    return ok and same_point(yb, ys, yq, r)


@inlined
def photon_base(sa, lp, v, r, stack):
    """Surface photon row v's base side, the same for its four shifts (photon_shift_loop's contract):
    (a = its nearest non-null ancestor's row q (-1: none), the row after a, the null interfaces the
    edge a -> y_s crosses (``gvpm_light._ancestor``); a re-evaluated towards y_s
    (``gvpm_light.parent_base_vol``); the recorded edge's (ok, optical depth, log pass probability)
    for the reconnection's T and P ratios (walked through the null interfaces: once per photon, not
    per shift); may a specular parent take the manifold walk (edge and chain in vacuum))."""
    no_edge = (False, _ZERO, 0.0)
    q, child, n_null = _ancestor(sa, lp, v)
    if q < 0:
        return q, child, n_null, (P_FAIL, _ZERO, (1.0, 1.0, 1.0), 0.0), no_edge, False
    pb = parent_base_vol(sa, lp, q, v)
    if pb[0] == P_SPECULAR:
        return q, child, n_null, pb, no_edge, n_null == 0 and _vacuum_chain(lp, v)
    if pb[0] == P_FAIL:
        return q, child, n_null, pb, no_edge, False
    return q, child, n_null, pb, _base_edge(sa, lp, q, child, n_null, v, r, stack), False


@inlined
def _reconnect(sa, lp, prm, v, pb, ystar, nstar, p2, r, stack):
    """Photon row v's parent a (base side ``pb``, :func:`photon_base`) reconnected through y* (normal
    nstar) to the offset photon y'_s, which must lie within r of the offset gather point p2 (Eq. 6
    through null interfaces, with the edge's media). Returns (status OK | FAIL | FAIL_SPECULAR (a
    specular parent), power ratio beta'_s / beta_s per channel, MIS density ratio, direction
    a -> y'_s, y'_s)."""
    q, child, n_null, pbase, edge, _ = pb
    ys = (lp.pos[v, 0], lp.pos[v, 1], lp.pos[v, 2])
    yq = (lp.pos[q, 0], lp.pos[q, 1], lp.pos[q, 2])
    d, dl = _dir(yq, ystar)
    if not dl > 0.0:
        return FAIL, _ZERO, 0.0, d, ys
    status, fr, pr = parent_offset_vol(sa, lp, q, pbase, d)
    if status != OK:
        return status, _ZERO, 0.0, d, ys
    # Eq. 6 through null interfaces: the first real surface on the ray a -> y*
    ok, yh, _, prim, n_o, tau_o, logp_o, med = walk_to_surface(sa, yq, _spawn(lp, q, yq, d), d, lp.medium[child],
                                                               stack)
    if not (ok and n_o == n_null and med == lp.medium[v]):
        return FAIL, _ZERO, 0.0, d, ys
    if vertex_class(sa.materials[sa.prim_info[prim, INFO_MAT]], prm.threshold) == L.V_SPECULAR:
        return FAIL, _ZERO, 0.0, d, ys                                     # no photon is stored there
    if not (yh[0] - p2[0]) ** 2 + (yh[1] - p2[1]) ** 2 + (yh[2] - p2[2]) ** 2 < r * r:
        return FAIL, _ZERO, 0.0, d, ys                                     # outside the offset kernel
    ok, tau_b, logp_b = edge
    geo = photon_geometry_ratio(yq, ys, (lp.nrm[v, 0], lp.nrm[v, 1], lp.nrm[v, 2]), ystar, nstar)
    if not (ok and geo > 0.0):
        return FAIL, _ZERO, 0.0, d, ys
    # T(a, y') / T(a, y) = exp(-(tau' - tau)) per channel: one exponential, no 0 / 0 in a dense medium
    f3 = (fr[0] * geo * math.exp(tau_b[0] - tau_o[0]), fr[1] * geo * math.exp(tau_b[1] - tau_o[1]),
          fr[2] * geo * math.exp(tau_b[2] - tau_o[2]))
    return OK, f3, pr * geo * math.exp(logp_o - logp_b), d, yh


@block
def reconnect_surface(sa, lp, prm, v, ystar, nstar, p2, r, stack):
    """The reconnection of surface photon row v through y* alone (:func:`photon_base` then the
    reconnection; the shift without the manifold branch and the reversibility check): (status,
    power ratio per channel, MIS density ratio, direction a -> y'_s, y'_s). For checks of a pair
    of shifts (tests/test_gvpm_full.py: the two MIS weights sum to one)."""
    return _reconnect(sa, lp, prm, v, photon_base(sa, lp, v, r, stack), ystar, nstar, p2, r, stack)


@block
def shift_surface_photon(sa, lp, mtab, prm, v, base, off, r, stack):
    """The light half of surface photon row v's shift from the base gather point ``base`` = (p, frame)
    to the offset one ``off`` = (p', ng', frame', wi', mat'), kernel radius r. Returns (status, the
    photon term at the offset before the camera weight, MIS density ratio offset / base): the
    contract of :func:`gdlearn.integrators.photon.gpm_gather.shift_photon`."""
    return shift_from_base(sa, lp, mtab, prm, v, photon_base(sa, lp, v, r, stack), base, off, r, stack)


@inlined
def shift_from_base(sa, lp, mtab, prm, v, pb, base, off, r, stack):
    """:func:`shift_surface_photon` from the photon's base side ``pb`` (:func:`photon_base`, computed
    once per photon for the four neighbours); inlined into the photon loop (photon_shift_loop)."""
    q = pb[0]
    if q < 0:
        return FAILED, _ZERO, 0.0
    p, frame = base
    p2, ng2, frame2, wi2, mat2 = off
    ys = (lp.pos[v, 0], lp.pos[v, 1], lp.pos[v, 2])
    ystar = offset_target(ys, p, frame, p2, frame2)                        # Eq. 5
    nstar = rotate((lp.nrm[v, 0], lp.nrm[v, 1], lp.nrm[v, 2]), frame, frame2)
    status, f3, ratio, d, yh = _reconnect(sa, lp, prm, v, pb, ystar, nstar, p2, r, stack)
    if status == FAIL_SPECULAR and pb[5]:                                  # chain and edge in vacuum
        ok, ratio3, pp, w_arr = manifold_photon(sa, lp, mtab, prm, v, q, ystar, nstar, r, p2, stack)
        return at_offset(MANIFOLD if ok else FAILED, lp, v, ratio3, pp, w_arr, off)
    if not (status == OK and _reversible(sa, lp, q, pb[1], ys, yh, ystar, p, frame, p2, frame2, r, stack)):
        return FAILED, _ZERO, 0.0
    return at_offset(RECONNECTED, lp, v, f3, ratio, d, off)
