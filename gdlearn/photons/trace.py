"""Light-path tracing (importance transport) into flat vertex records.

A light path starts on an emitter chosen by power (:mod:`gdlearn.photons.emit`) and walks the
scene by BSDF sampling (Veach 1997, Sec. 10.2; pbrt-v3 ``SPPMIntegrator`` photon pass), with the
two corrections importance transport needs:

* the adjoint BSDF of a refraction carries no radiance scaling: Mitsuba's and gdlearn's dielectrics
  scale radiance by eta_ti^2 on refraction (Veach 1997, Sec. 5.2), so a light path multiplies the
  sampled weight back by ``bsdf_eta(wi, wo)^2``;
* shading normals make the adjoint BSDF non-symmetric: the weight is multiplied by
  ``|wi.ns| |wo.ng| / (|wi.ng| |wo.ns|)`` (Veach 1997, Sec. 5.3.2; pbrt-v3
  ``CorrectShadingNormal``), exactly 1 on flat geometry.

Russian roulette from light depth ``rr_depth`` survives with ``min(max(bsdf weight), 0.95)`` per
bounce: the power of a path then stays about constant (pbrt-v3's photon pass, Mitsuba's cap).

Random numbers: light path j of pass i uses ``rand(seed, LIGHT_KEY0 + j, i, dim)`` with dims
0 emitter choice, 1-2 position, 3-4 direction, and for the scattering at vertex k >= 1
``5 + 6 (k - 1) + {0 lobe, 1-2 direction, 3 roulette, 4-5 reserved for media}``. The records are a
pure function of (seed, i, j): tracing is a ``prange`` over paths, each writing fixed slots of a
batch, then compacted in path order -- the same records for any thread count.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np
from numba import prange

from gdlearn.kernels import layout as L
from gdlearn.kernels.bsdf.dispatch import bsdf_eta, bsdf_pdf, bsdf_sample, sampled_lobe_class, vertex_class
from gdlearn.kernels.accel.bvh import STACK_SIZE, closest_hit_inline
from gdlearn.kernels.geometry import INFO_MAT, offset_origin, surface
from gdlearn.kernels.rng import LIGHT_KEY0, path_state, rand_at
from gdlearn.kernels.arrays import borrow
from gdlearn.kernels.vec import coordinate_system, dot, max3, to_local, to_world
from gdlearn.kernels.arrays import borrowed
from gdlearn.photons.emit import emitter_cdf, sample_emission
from gdlearn.photons.records import (F_DELTA_DIR, F_DELTA_OUT, F_DELTA_POS, F_PHOTON, K_EMITTER, K_SURFACE, LightPaths,
                      allocate, concatenate)
from gdlearn.kernels.jit import block, inlined, noalloc, rows

DIMS_START, DIMS_PER_BOUNCE = 5, 6
D_LOBE, D_U1, D_U2, D_RR = 0, 1, 2, 3


class TraceParams(NamedTuple):
    """Constants of a light-path walk (numba passes a NamedTuple as a struct).

    ``max_vertices``: scattering vertices after the emitter (Mitsuba's max_depth - 1, or fewer if
    the effects plan bounds the interior vertices); ``want_caustic`` / ``want_other``: does the plan
    ask for paths whose first scattering vertex is specular (L S+ D ..., caustics) / is not?"""
    max_vertices: int
    rr_depth: int
    threshold: float
    want_caustic: bool
    want_other: bool


@inlined
def _put(rec, k, p, ng, ns, d):
    for c in range(3):
        rec.pos[k, c] = p[c]
        rec.nrm[k, c] = ng[c]
        rec.nsh[k, c] = ns[c]
        rec.d_in[k, c] = d[c]


@inlined
def _put_meta(rec, k, beta, pdf_fwd, kind, obj, prim, flags):
    for c in range(3):
        rec.beta[k, c] = beta[c]
    rec.pdf_fwd[k] = pdf_fwd
    rec.pdf_rev[k] = 0.0
    rec.kind[k] = kind
    rec.obj[k] = obj
    rec.prim[k] = prim
    rec.lobe[k] = -1
    rec.flags[k] = flags


@inlined
def _adjoint_weight(mat, w, wi, wo, wi_w, wo_w, ng, ns):
    """The importance-transport weight from bsdf_sample's radiance weight ``w`` (module docstring)."""
    e = bsdf_eta(mat, wi, wo)
    den = abs(dot(wi_w, ng)) * abs(dot(wo_w, ns))
    if not den > 0.0:
        return (0.0, 0.0, 0.0)
    s = e * e * abs(dot(wi_w, ns)) * abs(dot(wo_w, ng)) / den
    return (w[0] * s, w[1] * s, w[2] * s)


@noalloc
def trace_one(sa, cdf, prm, seed, pass_index, j, rec, base, stack):
    """Trace light path j of pass ``pass_index`` into rows base, base+1, ...; returns its vertex count."""
    h = path_state(seed, LIGHT_KEY0 + j, pass_index)
    u = (rand_at(h, 0), rand_at(h, 1), rand_at(h, 2), rand_at(h, 3), rand_at(h, 4))
    em, prim, p, n, d, beta, pdf_pos, pdf_dir, dpos, ddir = sample_emission(sa, cdf, u)
    if em < 0:
        return 0
    _put(rec, base, p, n, n, d)
    _put_meta(rec, base, beta, pdf_pos, K_EMITTER, em, prim, (F_DELTA_POS if dpos else 0) | (F_DELTA_DIR if ddir else 0))
    rec.parent[base] = -1
    rec.path[base] = j
    rec.depth[base] = 0
    o = offset_origin(p, n, d) if prim >= 0 else p
    caustic = False
    nv = 1
    while nv <= prm.max_vertices:
        t, prim, uu, vv = closest_hit_inline(sa.nodes, sa.node_info, sa.prims, sa.prim_info, o, d, 0.0, math.inf, stack)
        if prim < 0:
            break
        p, ng, ns = surface(sa.prims, sa.prim_info, prim, o, d, t, uu, vv)
        k = base + nv
        mid = sa.prim_info[prim, INFO_MAT]
        mat = sa.materials[mid]
        store = vertex_class(mat, prm.threshold) != L.V_SPECULAR and (
            (nv == 1 and prm.want_other) or (nv > 1 and (prm.want_caustic if caustic else prm.want_other)))
        _put(rec, k, p, ng, ns, d)
        # area-measure pdf of this vertex: the parent's solid-angle pdf times |cos| / dist^2
        _put_meta(rec, k, beta, pdf_dir * abs(dot(d, ng)) / (t * t), K_SURFACE, mid, prim, F_PHOTON if store else 0)
        rec.parent[k] = k - 1
        rec.path[k] = j
        rec.depth[k] = nv
        nv += 1
        if nv > prm.max_vertices:
            break
        s, tt = coordinate_system(ns)
        wi_w = (-d[0], -d[1], -d[2])
        wi = to_local(wi_w, s, tt, ns)
        b = 5 + DIMS_PER_BOUNCE * (nv - 2)
        u_lobe = rand_at(h, b + D_LOBE)
        wo, w, pdf, delta = bsdf_sample(mat, wi, u_lobe, rand_at(h, b + D_U1), rand_at(h, b + D_U2))
        if not pdf > 0.0:
            break
        wo_w = to_world(wo, s, tt, ns)
        w = _adjoint_weight(mat, w, wi, wo, wi_w, wo_w, ng, ns)
        lobe = sampled_lobe_class(mat, wi, u_lobe, delta, prm.threshold)
        rec.lobe[k] = lobe
        if delta:
            rec.flags[k] |= F_DELTA_OUT
        else:       # reverse pdf of the parent: sampled from here towards it, to area at the parent
            pn = (rec.nrm[k - 1, 0], rec.nrm[k - 1, 1], rec.nrm[k - 1, 2])
            cp = abs(dot(pn, d)) if (pn[0] != 0.0 or pn[1] != 0.0 or pn[2] != 0.0) else 1.0
            rec.pdf_rev[k - 1] = bsdf_pdf(mat, wo, wi) * cp / (t * t)
        if nv == 2:     # the first scattering vertex decides caustic (L S ...) or not
            caustic = lobe == L.V_SPECULAR
            if (caustic and not prm.want_caustic) or (not caustic and not prm.want_other):
                break
        if nv - 1 >= prm.rr_depth:
            q = min(max3(w), 0.95)
            if rand_at(h, b + D_RR) >= q:
                break
            w = (w[0] / q, w[1] / q, w[2] / q)
        beta = (beta[0] * w[0], beta[1] * w[1], beta[2] * w[2])
        if not max3(beta) > 0.0:
            break
        d = wo_w
        o = offset_origin(p, ng, d)
        pdf_dir = pdf
    return nv


@block
def _borrow_rec(r):
    return LightPaths(borrow(r.pos), borrow(r.nrm), borrow(r.nsh), borrow(r.d_in), borrow(r.beta),
                      borrow(r.pdf_fwd), borrow(r.pdf_rev), borrow(r.kind), borrow(r.obj), borrow(r.prim),
                      borrow(r.lobe), borrow(r.flags), borrow(r.parent), borrow(r.path), borrow(r.depth))


@block
def trace_batch(sa, cdf, prm, seed, pass_index, j0, slots, nv):
    """Light paths j0 .. j0 + len(nv) - 1 into fixed slots (max_vertices + 1 rows each); ``nv[i]``
    receives path i's vertex count."""
    # borrowed arrays: no atomic reference counts shared by the threads (scene.compile.borrowed)
    _trace_rows(borrowed(sa), cdf, prm, seed, pass_index, j0, _borrow_rec(slots), nv)


@rows
def _trace_rows(sa, cdf, prm, seed, pass_index, j0, slots, nv):
    per = prm.max_vertices + 1
    for i in prange(nv.shape[0]):
        stack = np.empty(STACK_SIZE, dtype=np.int32)
        nv[i] = trace_one(sa, cdf, prm, seed, pass_index, j0 + i, slots, i * per, stack)


@block
def compact(slots, per, nv, off, out):
    """Copy path i's ``nv[i]`` slot rows to rows off[i] ... of ``out``, parents re-indexed."""
    # borrowed views, as trace_batch: no reference counts shared by the threads
    _compact_rows(_borrow_rec(slots), per, nv, off, _borrow_rec(out))


@rows
def _compact_rows(slots, per, nv, off, out):
    for i in prange(nv.shape[0]):
        _copy_path(slots, i * per, nv[i], off[i], out)


# a function of its own on purpose: written directly in the prange body, stores into the fields of
# a NamedTuple of arrays were lost (numba 0.68's parfor lowering; tests/test_photons_trace.py
# compares the compacted records with the slots)
@block
def _copy_path(slots, s0, n, t0, out):
    for v in range(n):
        s = s0 + v
        t = t0 + v
        for c in range(3):
            out.pos[t, c] = slots.pos[s, c]
            out.nrm[t, c] = slots.nrm[s, c]
            out.nsh[t, c] = slots.nsh[s, c]
            out.d_in[t, c] = slots.d_in[s, c]
            out.beta[t, c] = slots.beta[s, c]
        out.pdf_fwd[t] = slots.pdf_fwd[s]
        out.pdf_rev[t] = slots.pdf_rev[s]
        out.kind[t] = slots.kind[s]
        out.obj[t] = slots.obj[s]
        out.prim[t] = slots.prim[s]
        out.lobe[t] = slots.lobe[s]
        out.flags[t] = slots.flags[s]
        out.parent[t] = t - 1 if v > 0 else -1
        out.path[t] = slots.path[s]
        out.depth[t] = slots.depth[s]


class LightTracer:
    """Traces batches of light paths with preallocated slots (reused across passes).

    ``LightTracer(sa, params, batch=16384).trace(seed, pass_index, j0, n) -> LightPaths`` for
    light paths j0 .. j0 + n - 1; ``threads`` sets numba's thread count while tracing."""

    def __init__(self, sa, params: TraceParams, batch: int = 16384, threads=None):
        self.sa, self.params, self.threads = sa, params, threads
        self.cdf = emitter_cdf(sa)
        self.batch = max(1024, min(int(batch), (1 << 17) // (params.max_vertices + 1)))   # slots ~<= 20 MB
        self.per = params.max_vertices + 1
        self.slots = allocate(self.batch * self.per)

    def trace(self, seed: int, pass_index: int, j0: int, n: int) -> LightPaths:
        parts = []
        old = numba.get_num_threads()
        if self.threads is not None:
            numba.set_num_threads(int(self.threads))
        try:
            for a in range(j0, j0 + n, self.batch):
                m = min(self.batch, j0 + n - a)
                nv = np.zeros(m, dtype=np.int64)
                trace_batch(self.sa, self.cdf, self.params, int(seed), int(pass_index), int(a), self.slots, nv)
                off = np.zeros(m, dtype=np.int64)
                np.cumsum(nv[:-1], out=off[1:])
                out = allocate(int(nv.sum()))
                compact(self.slots, self.per, nv, off, out)
                parts.append(out)
        finally:
            numba.set_num_threads(old)
        return parts[0] if len(parts) == 1 else concatenate(parts)
