"""The camera side of surface photon mapping: gather points and the photon density estimate.

A gather (camera) path is traced from the pixel through specular vertices -- the roughness
classification the shifts use (``vertex_class`` with the plan's threshold: delta lobes and
microfacets below it) -- to the first non-specular vertex, the *gather point* (Hachisuka & Jensen
2009, Sec. 3; PHOTONS.md Sec. 1.7). Emission the path sees on the way (directly or through the
specular chain) is added exactly. At the gather point the photons within radius r give::

    L(x, w) ~ sum_p f(x, w, w_p) Phi_p / (|w_p . n_g| pi r^2)           (Jensen 2001, Ch. 7, the radiance estimate)

with Phi_p the photon's power per emitted light path (the caller divides by the number emitted)
and the ``1 / |w_p . n_g|`` turning the photon's flux per geometric area into the cosine-free form
``bsdf_eval`` (``f |w_p . n_s|``) needs. A smooth plastic (a delta coating over a diffuse base) is
split per sample: the delta lobe continues the chain, the base becomes a gather point weighted by
1 / P(base).

A photon counts only if the whole path obeys the scene's ``max_depth`` (Mitsuba's segments) and,
when the effects plan asks for a subset, if the full path's class (:mod:`gdlearn.kernels.pathclass`,
built from the camera vertices, the gather point and the photon's light vertices found through
``parent``) is wanted.

With ``nee`` (``direct="nee"`` in sppm/ppm) the direct light at the gather point is estimated by
emitter sampling (:func:`direct`) and photons at the light path's first vertex are left out.

Random numbers: pixel key y W + x, sample 2 i + h for half h of pass i; dims 0-1 film position,
then ``2 + 3 b + {0 lobe, 1-2 direction}`` at camera vertex b, and ``D_NEE + {0 emitter, 1-2
point}`` for the emitter sample at the gather point.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import prange

from gdlearn.kernels import layout as L
from gdlearn.kernels.bsdf.dispatch import bsdf_eval, bsdf_sample, sampled_lobe_class, vertex_class
from gdlearn.kernels.bsdf.plastic import plastic_spec_prob
from gdlearn.kernels.accel.bvh import STACK_SIZE, closest_hit_inline
from gdlearn.kernels.camera import camera_ray
from gdlearn.kernels.geometry import INFO_EMITTER, INFO_MAT, offset_origin, surface
from gdlearn.kernels.lights import eval_emitter, sample_emitter
from gdlearn.kernels.scene_query import occluded
from gdlearn.kernels.pathclass import pc_class, pc_init, pc_push
from gdlearn.kernels.rng import path_state, rand_at
from gdlearn.kernels.vec import coordinate_system, dot, to_local, to_world
from gdlearn.kernels.arrays import borrow
from gdlearn.photons.grid import HashGrid, bucket, cell_of
from gdlearn.photons.records import F_DELTA_OUT, K_SURFACE
from gdlearn.photons.trace import _borrow_rec
from gdlearn.kernels.arrays import borrowed
from gdlearn.kernels.jit import block, inlined, rows


class GatherParams(NamedTuple):
    max_depth: int        # Mitsuba's max_depth (path segments), a loop bound
    threshold: float      # roughness threshold of the vertex classification
    mask: int             # effect classes to keep
    filter_classes: bool  # does the mask exclude some photon-path class (walk the light vertices)?
    nee: bool = False     # direct light at the gather point by emitter sampling, not by photons
    parents: int = 0      # photon subset by parent vertex: 0 all, 1 specular parents only, 2 all others


class GatherOut(NamedTuple):
    phi: np.ndarray       # (2, H, W, 3): camera weight x sum of photon terms, per half
    m: np.ndarray         # (2, H, W): photons found (SPPM's M)
    le: np.ndarray        # (2, H, W, 3): emission seen through the specular chain
    foot: np.ndarray      # (2, H, W): pixel footprint at the gather point (0: no gather point)
    bad: np.ndarray       # (H,): non-finite terms dropped
    ld: np.ndarray        # (2, H, W, 3): camera weight x direct light by emitter sampling (nee)


#: first dimension of the gather point's emitter sample (beyond any camera vertex's block)
D_NEE = 1 << 20


@inlined
def _wanted(mask, state):
    return (mask >> pc_class(state)) & 1 == 1


@inlined
def _plus(le, beta, e):
    return (le[0] + beta[0] * e[0], le[1] + beta[1] * e[1], le[2] + beta[2] * e[2])


#: what :func:`_leave` decided at a camera vertex
GATHER, CONTINUE, STOP = 0, 1, 2


@block
def _leave(mat, prm, h, b, wi, state, beta):
    """At a camera vertex with local incident direction ``wi``: is it the gather point (GATHER),
    does the specular chain go on (CONTINUE, with the sampled local direction), or does the path
    end (STOP)? Returns (decision, wo, beta, state). A smooth plastic's diffuse base becomes the
    gather point weighted by 1 / P(base); its delta coating continues the chain."""
    vc = vertex_class(mat, prm.threshold)
    plastic = int(mat[L.MAT_TYPE]) == L.PLASTIC
    if vc != L.V_SPECULAR and not plastic:
        return GATHER, wi, beta, pc_push(state, vc)
    u_lobe = rand_at(h, b)
    wo, w, pdf, delta = bsdf_sample(mat, wi, u_lobe, rand_at(h, b + 1), rand_at(h, b + 2))
    if not pdf > 0.0:
        return STOP, wo, beta, state
    if plastic and not delta:
        pb = 1.0 - plastic_spec_prob(mat, abs(wi[2]))
        return GATHER, wi, (beta[0] / pb, beta[1] / pb, beta[2] / pb), pc_push(state, L.V_DIFFUSE)
    state = pc_push(state, sampled_lobe_class(mat, wi, u_lobe, delta, prm.threshold))
    return CONTINUE, wo, (beta[0] * w[0], beta[1] * w[1], beta[2] * w[2]), state


@block
def gather_path(sa, prm, h, o, d, stack):
    """Trace to the gather point. Returns (ok, p, ng, frame n/s/t, wi, mat row, weight, state, m,
    travelled distance, emission): ``m`` camera vertices before the gather point."""
    le = (0.0, 0.0, 0.0)
    beta = (1.0, 1.0, 1.0)
    state = pc_init()
    zero = (0.0, 0.0, 0.0)
    travelled = 0.0
    tmax = math.inf
    m = 0
    while True:
        t, prim, u, v = closest_hit_inline(sa.nodes, sa.node_info, sa.prims, sa.prim_info, o, d, 0.0, tmax, stack)
        if prim < 0:
            if sa.env >= 0 and _wanted(prm.mask, state):
                le = _plus(le, beta, eval_emitter(sa.emitters, sa.env, d, d))
            break
        travelled += t
        p, ng, ns = surface(sa.prims, sa.prim_info, prim, o, d, t, u, v)
        em = sa.prim_info[prim, INFO_EMITTER]
        if em >= 0 and _wanted(prm.mask, state):
            le = _plus(le, beta, eval_emitter(sa.emitters, em, ns, d))
        if m + 2 > prm.max_depth:          # no room for a photon's light segment after this vertex
            break
        mid = sa.prim_info[prim, INFO_MAT]
        s, tt = coordinate_system(ns)
        wi = to_local((-d[0], -d[1], -d[2]), s, tt, ns)
        what, wo, beta, state = _leave(sa.materials[mid], prm, h, 2 + 3 * m, wi, state, beta)
        if what == GATHER:
            return True, p, ng, (ns, s, tt), wi, mid, beta, state, m, travelled, le
        if what == STOP:
            break
        d = to_world(wo, s, tt, ns)
        o = offset_origin(p, ng, d)
        tmax = math.inf
        m += 1
    return False, zero, zero, (zero, zero, zero), zero, -1, beta, state, m, travelled, le


@block
def direct(sa, p, ng, frame, wi, mat, h, stack):
    """Direct light at the gather point by emitter sampling alone, unweighted: the gather path
    stops here, so no BSDF sample could find the emitter and MIS has no second strategy (the
    light path's first vertex, which a photon map would use instead, is left out of the density:
    every path is counted once). pbrt-v3's ``SPPMIntegrator`` does the same at its visible points."""
    ns, s, tt = frame
    em, q, nq, dl, dist, w_em, pdf_em, pdf_a, delta = sample_emitter(
        sa.emitters, sa.em_prims, sa.em_cdf, sa.prims, sa.prim_info, p,
        rand_at(h, D_NEE), rand_at(h, D_NEE + 1), rand_at(h, D_NEE + 2))
    if em < 0:
        return (0.0, 0.0, 0.0)
    f = bsdf_eval(mat, wi, to_local(dl, s, tt, ns))
    if (f[0] == 0.0 and f[1] == 0.0 and f[2] == 0.0) or occluded(sa, p, ng, q, stack):
        return (0.0, 0.0, 0.0)
    return (f[0] * w_em[0], f[1] * w_em[1], f[2] * w_em[2])


@inlined
def specular_vertex(lp, q):
    """Did surface row ``q`` leave by a specular lobe (delta, or a microfacet below the roughness
    threshold)? Such a parent is what sends GPM's shift to the manifold branch."""
    return (lp.flags[q] & F_DELTA_OUT) != 0 or not (lp.lobe[q] == L.V_DIFFUSE or lp.lobe[q] == L.V_GLOSSY)


@inlined
def parent_ok(lp, v, prm):
    """Is photon row ``v`` in the gathered subset ``prm.parents``: every photon (0), only one whose
    parent y_{s-1} is a specular surface vertex (1: the subset of Hua et al. 2017's Fig. 4, the
    photons GPM's manifold branch shifts), or only the others (2: the complement)?"""
    if prm.parents == 0:
        return True
    q = lp.parent[v]
    spec = q >= 0 and lp.kind[q] == K_SURFACE and specular_vertex(lp, q)
    return spec == (prm.parents == 1)


@block
def _class_ok(lp, v, state, mask):
    """Is the full path (camera state incl. the gather point, then the photon's light vertices
    y_{k-1} .. y_1 found through ``parent``) of a wanted class?"""
    q = lp.parent[v]
    while q >= 0 and lp.depth[q] >= 1:
        if lp.lobe[q] >= 0:
            state = pc_push(state, lp.lobe[q])
        q = lp.parent[q]
    return _wanted(mask, state)


@block
def density(lp, grid, prm, gp, r):
    """(sum of f Phi / |cos_g| over photons within r of the gather point ``gp``, photon count)."""
    p, ng, frame, wi, mat, state, m = gp
    ns, s, tt = frame
    a0 = 0.0
    a1 = 0.0
    a2 = 0.0
    cnt = 0
    r2 = r * r
    for ix in range(cell_of(p[0] - r, grid.inv_h), cell_of(p[0] + r, grid.inv_h) + 1):
        for iy in range(cell_of(p[1] - r, grid.inv_h), cell_of(p[1] + r, grid.inv_h) + 1):
            for iz in range(cell_of(p[2] - r, grid.inv_h), cell_of(p[2] + r, grid.inv_h) + 1):
                bk = bucket(ix, iy, iz, grid.mask)
                for k in range(grid.start[bk], grid.start[bk + 1]):
                    if grid.cell[k, 0] != ix or grid.cell[k, 1] != iy or grid.cell[k, 2] != iz:
                        continue
                    dx = grid.pos[k, 0] - p[0]
                    dy = grid.pos[k, 1] - p[1]
                    dz = grid.pos[k, 2] - p[2]
                    if dx * dx + dy * dy + dz * dz >= r2:
                        continue
                    v = grid.order[k]                 # the photon's vertex row
                    if lp.depth[v] + m + 1 > prm.max_depth:
                        continue
                    if prm.filter_classes and not _class_ok(lp, v, state, prm.mask):
                        continue
                    if not parent_ok(lp, v, prm):
                        continue
                    cnt += 1
                    wo_w = (-lp.d_in[v, 0], -lp.d_in[v, 1], -lp.d_in[v, 2])
                    cg = abs(dot(wo_w, ng))
                    if not cg > 1e-9:                  # grazing: the flux per area is ill-defined
                        continue
                    f = bsdf_eval(mat, wi, to_local(wo_w, s, tt, ns))
                    a0 += f[0] * lp.beta[v, 0] / cg
                    a1 += f[1] * lp.beta[v, 1] / cg
                    a2 += f[2] * lp.beta[v, 2] / cg
    return (a0, a1, a2), cnt


@block
def gather_rows(sa, lp, grids, prm, seed, sample0, radius, out):
    """Every pixel's two gather points (samples sample0 + h, half h queries grids[h]) into ``out``;
    ``radius`` (H x W) is the kernel radius per pixel."""
    # borrowed arrays: no atomic reference counts shared by the threads (scene.compile.borrowed); the
    # two grids go separately: numba's parfor refuses a tuple of NamedTuples as an argument
    _gather_rows(borrowed(sa), _borrow_rec(lp), _borrow_grid(grids[0]), _borrow_grid(grids[1]), prm, seed,
                 sample0, radius, _borrow_out(out))


@block
def _borrow_grid(g):
    return HashGrid(borrow(g.pos), borrow(g.cell), borrow(g.order), borrow(g.start), g.inv_h, g.mask)


@block
def _borrow_out(o):
    return GatherOut(borrow(o.phi), borrow(o.m), borrow(o.le), borrow(o.foot), borrow(o.bad), borrow(o.ld))


@block
def pixel_angle(cam, fx, fy, d):
    """The angle a pixel subtends around the ray d (PHOTONS.md Sec. 1.6: footprint = unfolded distance x it)."""
    d1 = camera_ray(cam, fx + 1.0, fy)[1]
    d2 = camera_ray(cam, fx, fy + 1.0)[1]
    dd1 = math.sqrt((d1[0] - d[0]) ** 2 + (d1[1] - d[1]) ** 2 + (d1[2] - d[2]) ** 2)
    dd2 = math.sqrt((d2[0] - d[0]) ** 2 + (d2[1] - d[1]) ** 2 + (d2[2] - d[2]) ** 2)
    return max(dd1, dd2)


@inlined
def put_finite(dst, hh, y, x, v):
    """Write the RGB value v into dst[hh, y, x] if it is finite (else leave it); returns whether it was."""
    if not (np.isfinite(v[0]) and np.isfinite(v[1]) and np.isfinite(v[2])):
        return False
    for c in range(3):
        dst[hh, y, x, c] = v[c]
    return True


@rows
def _gather_rows(sa, lp, ga, gb, prm, seed, sample0, radius, out):
    for y in prange(radius.shape[0]):
        out.bad[y] = _gather_row(sa, lp, (ga, gb), prm, seed, sample0, radius, out, y)


# a function of its own: stores into a NamedTuple's arrays written directly in a prange body are
# lost (numba 0.68; see photons/trace.py)
@block
def _gather_row(sa, lp, grids, prm, seed, sample0, radius, out, y):
    w = radius.shape[1]
    cam = sa.camera
    nbad = 0
    stack = np.empty(STACK_SIZE, dtype=np.int32)      # one per row, not one per gather path
    for x in range(w):
        for hh in range(2):
            h = path_state(seed, y * w + x, sample0 + hh)
            fx = x + rand_at(h, 0)
            fy = y + rand_at(h, 1)
            o, d, tmax = camera_ray(cam, fx, fy)
            ok, p, ng, frame, wi, mid, beta, state, m, dist, le = gather_path(sa, prm, h, o, d, stack)
            for c in range(3):
                out.le[hh, y, x, c] = le[c]
                out.phi[hh, y, x, c] = 0.0
                out.ld[hh, y, x, c] = 0.0
            out.m[hh, y, x] = 0.0
            out.foot[hh, y, x] = 0.0
            if not ok:
                continue
            out.foot[hh, y, x] = dist * pixel_angle(cam, fx, fy, d)
            if prm.nee and _wanted(prm.mask, state):
                e = direct(sa, p, ng, frame, wi, sa.materials[mid], h, stack)
                if not put_finite(out.ld, hh, y, x, (beta[0] * e[0], beta[1] * e[1], beta[2] * e[2])):
                    nbad += 1
            r = radius[y, x]
            if not r > 0.0:
                continue
            phi, cnt = density(lp, grids[hh], prm, (p, ng, frame, wi, sa.materials[mid], state, m), r)
            if put_finite(out.phi, hh, y, x, (beta[0] * phi[0], beta[1] * phi[1], beta[2] * phi[2])):
                out.m[hh, y, x] = cnt
            else:
                nbad += 1
    return nbad
