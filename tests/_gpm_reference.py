"""The GPM camera pass as it was before it was made fast (gpm_gather at main 6e8a905: one photon at a
time, its four shifts one after the other, each a call of ``shift_photon`` that re-evaluates the
base parent, and a buffer write per term): the straightforward reading of Hua et al. 2017, Sec. 4
and Eq. 11, kept here as the reference the fast kernel must reproduce bit for bit
(tests/golden/passes.py records its buffers, tests/test_photon_fast_passes.py compares). The
per-photon loops and the shift itself are copied; the camera paths, the projection and the manifold
walk are the package's own helpers (gpm_light), whose results the rewrite leaves unchanged; the
parent's re-evaluation (gpm_light.parent_factor, since split into a base half computed once per
photon and an offset half) is copied as it was."""
import math

import numpy as np
from numba import prange

from gdlearn.kernels.accel.bvh import STACK_SIZE, closest_hit_inline
from gdlearn.kernels.arrays import borrow, borrowed
from gdlearn.kernels.bsdf.dispatch import bsdf_eval
from gdlearn.kernels.camera import camera_ray
from gdlearn.kernels.geometry import offset_origin
from gdlearn.kernels.jit import block, rows
from gdlearn.kernels.rng import path_state, rand_at
from gdlearn.kernels.vec import dot, to_local
from gdlearn.photons import grid as hashgrid
from gdlearn.photons.trace import _borrow_rec
from gdlearn.integrators.photon.gather import _borrow_grid, _class_ok, gather_path, parent_ok, pixel_angle
from gdlearn.integrators.photon.gpm_gather import FAILED, MANIFOLD, RECONNECTED, GpmOut
from gdlearn.integrators.photon.photon_shift_loop import finite3 as _finite3, put as _put
from gdlearn.integrators.photon.gather import specular_vertex
from gdlearn.integrators.photon.gpm_light import _dir, project, same_point
from gdlearn.integrators.photon.photon_manifold import manifold_photon
from gdlearn.kernels.bsdf.dispatch import bsdf_pdf
from gdlearn.kernels.vec import coordinate_system
from gdlearn.photons.records import K_EMITTER, K_SURFACE
from gdlearn.photons.trace import _adjoint_weight
from gdlearn.shifts.photon import emission_profile
from gdlearn.shifts.mis import mis_weight_from_log_ratio
from gdlearn.shifts.photon import offset_target, photon_geometry_ratio, rotate
from gdlearn.shifts.replay import SHIFT_DX, SHIFT_DY


@block
def reference_rows(sa, lp, grids, mtab, prm, seed, sample0, radius, out):
    """gpm_gather.gpm_rows as it was: every pixel's two base gather points and their four shifts into
    ``out`` (a :class:`GpmOut`)."""
    _gpm_rows(borrowed(sa), _borrow_rec(lp), _borrow_grid(grids[0]), _borrow_grid(grids[1]), borrow(mtab), prm, seed,
              sample0, radius, GpmOut(borrow(out.phi), borrow(out.le), borrow(out.m), borrow(out.foot),
                                      borrow(out.count), borrow(out.bad)))


@rows
def _gpm_rows(sa, lp, ga, gb, mtab, prm, seed, sample0, radius, out):
    for y in prange(radius.shape[0]):
        out.bad[y] = _gpm_row(sa, lp, (ga, gb), mtab, prm, seed, sample0, radius, out, y)


@block
def parent_factor(sa, lp, q, v, d_new):
    one = (1.0, 1.0, 1.0)
    yq = (lp.pos[q, 0], lp.pos[q, 1], lp.pos[q, 2])
    d_b, _ = _dir(yq, (lp.pos[v, 0], lp.pos[v, 1], lp.pos[v, 2]))
    nq = (lp.nrm[q, 0], lp.nrm[q, 1], lp.nrm[q, 2])
    if lp.kind[q] == K_EMITTER:
        fb, pb = emission_profile(sa.emitters, lp.obj[q], nq, d_b)
        fo, po = emission_profile(sa.emitters, lp.obj[q], nq, d_new)
        if not (fb > 0.0 and fo > 0.0 and pb > 0.0 and po > 0.0):
            return 1, one, 0.0
        r = fo / fb
        return 0, (r, r, r), po / pb
    if lp.kind[q] != K_SURFACE:
        return 1, one, 0.0
    if specular_vertex(lp, q):
        return 2, one, 0.0
    if not dot(d_b, nq) * dot(d_new, nq) > 0.0:
        return 1, one, 0.0
    mat = sa.materials[lp.obj[q]]
    ns = (lp.nsh[q, 0], lp.nsh[q, 1], lp.nsh[q, 2])
    s, t = coordinate_system(ns)
    wi_w = (-lp.d_in[q, 0], -lp.d_in[q, 1], -lp.d_in[q, 2])
    wi = to_local(wi_w, s, t, ns)
    wb = to_local(d_b, s, t, ns)
    wo = to_local(d_new, s, t, ns)
    fb = _adjoint_weight(mat, bsdf_eval(mat, wi, wb), wi, wb, wi_w, d_b, nq, ns)
    fo = _adjoint_weight(mat, bsdf_eval(mat, wi, wo), wi, wo, wi_w, d_new, nq, ns)
    pb = bsdf_pdf(mat, wi, wb)
    po = bsdf_pdf(mat, wi, wo)
    if not (pb > 0.0 and po > 0.0):
        return 1, one, 0.0
    for c in range(3):
        if (fb[c] > 0.0) != (fo[c] > 0.0):
            return 1, one, 0.0
    r = (_ratio(fo[0], fb[0]), _ratio(fo[1], fb[1]), _ratio(fo[2], fb[2]))
    return 0, r, po / pb


@block
def _ratio(a, b):
    return a / b if b > 0.0 else 0.0


@block
def shift_photon(sa, lp, mtab, prm, v, base, off, r, stack):
    zero = (0.0, 0.0, 0.0)
    p, frame = base
    p2, ng2, frame2, wi2, mat2 = off
    q = lp.parent[v]
    if q < 0:
        return FAILED, zero, 0.0
    ys = (lp.pos[v, 0], lp.pos[v, 1], lp.pos[v, 2])
    yq = (lp.pos[q, 0], lp.pos[q, 1], lp.pos[q, 2])
    ystar = offset_target(ys, p, frame, p2, frame2)                        # Eq. 5
    nv = (lp.nrm[v, 0], lp.nrm[v, 1], lp.nrm[v, 2])
    nstar = rotate(nv, frame, frame2)
    d, dl = _dir(yq, ystar)
    if not dl > 0.0:
        return FAILED, zero, 0.0
    status, fr, pr = parent_factor(sa, lp, q, v, d)
    if status == 2:                                                        # a specular parent
        ok, ratio3, pp, w_arr = manifold_photon(sa, lp, mtab, prm, v, q, ystar, nstar, r, p2, stack)
        return _at_offset(MANIFOLD if ok else FAILED, lp, v, ratio3, pp, w_arr, off)
    if status != 0:
        return FAILED, zero, 0.0
    ok, _, yh, _ = project(sa, prm, yq, (lp.nrm[q, 0], lp.nrm[q, 1], lp.nrm[q, 2]), ystar, p2, r, stack)
    if not (ok and _reversible(sa, lp, q, ys, yh, ystar, p, frame, p2, frame2, r, stack)):
        return FAILED, zero, 0.0
    geo = photon_geometry_ratio(yq, ys, nv, ystar, nstar)
    if not geo > 0.0:
        return FAILED, zero, 0.0
    return _at_offset(RECONNECTED, lp, v, (fr[0] * geo, fr[1] * geo, fr[2] * geo), pr * geo, d, off)


@block
def _at_offset(status, lp, v, ratio3, ratio, w_arr, off):
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


@block
def _reversible(sa, lp, q, ys, yh, ystar, p, frame, p2, frame2, r, stack):
    yq = (lp.pos[q, 0], lp.pos[q, 1], lp.pos[q, 2])
    if same_point(yh, ystar, yq, r):
        return True
    d, dl = _dir(yq, offset_target(yh, p2, frame2, p, frame))
    if not dl > 0.0:
        return False
    o = offset_origin(yq, (lp.nrm[q, 0], lp.nrm[q, 1], lp.nrm[q, 2]), d)
    t, prim, u, w = closest_hit_inline(sa.nodes, sa.node_info, sa.prims, sa.prim_info, o, d, 0.0, math.inf, stack)
    return prim >= 0 and same_point((o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]), ys, yq, r)


@block
def _gpm_row(sa, lp, grids, mtab, prm, seed, sample0, radius, out, y):
    hgt, w = radius.shape
    cam = sa.camera
    nbad = 0
    stack = np.empty(STACK_SIZE, dtype=np.int32)
    cand = np.empty(4096, dtype=np.int64)
    o_ok = np.zeros(4, dtype=np.bool_)
    o_p = np.zeros((4, 3))
    o_ng = np.zeros((4, 3))
    o_fr = np.zeros((4, 3, 3))
    o_wi = np.zeros((4, 3))
    o_mat = np.zeros(4, dtype=np.int64)
    o_beta = np.zeros((4, 3))
    for x in range(w):
        for hh in range(2):
            h = path_state(seed, y * w + x, sample0 + hh)
            fx = x + rand_at(h, 0)
            fy = y + rand_at(h, 1)
            o, d, tmax = camera_ray(cam, fx, fy)
            ok, p, ng, frame, wi, mid, beta, state, m, dist, le = gather_path(sa, prm, h, o, d, stack)
            if _finite3(le):
                _put(out.le, hh, 0, y, x, le, 1.0)
            for k in range(4):
                o_ok[k] = False
                xo, yo = x + SHIFT_DX[k], y + SHIFT_DY[k]
                if not (0 <= xo < w and 0 <= yo < hgt):
                    if _finite3(le):
                        _put(out.le, hh, 1 + k, y, x, le, -1.0)
                    continue
                o2, d2, _ = camera_ray(cam, fx + SHIFT_DX[k], fy + SHIFT_DY[k])
                ok2, p2, ng2, fr2, wi2, mid2, beta2, state2, m2, _, le2 = gather_path(sa, prm, h, o2, d2, stack)
                if _finite3(le) and _finite3(le2):
                    _put(out.le, hh, 1 + k, y, x, (le2[0] - le[0], le2[1] - le[1], le2[2] - le[2]), 0.5)
                    _put(out.le, hh, 5 + k, y, x, le2, 0.5)
                if ok and ok2 and m2 == m and state2 == state:
                    o_ok[k] = True
                    for c in range(3):
                        o_p[k, c] = p2[c]
                        o_ng[k, c] = ng2[c]
                        o_wi[k, c] = wi2[c]
                        o_beta[k, c] = beta2[c]
                        for a in range(3):
                            o_fr[k, a, c] = fr2[a][c]
                    o_mat[k] = mid2
            if not ok:
                continue
            out.foot[hh, y, x] = dist * pixel_angle(cam, fx, fy, d)
            r = radius[y, x]
            if not r > 0.0:
                continue
            n = hashgrid.query(grids[hh], p, r, cand)
            if n > cand.shape[0]:
                cand = np.empty(2 * n, dtype=np.int64)
                n = hashgrid.query(grids[hh], p, r, cand)
            nbad += _shift_photons(sa, lp, mtab, prm, out, hh, y, x, (p, ng, frame, wi, mid, beta, state, m), r, cand, n,
                                   (o_ok, o_p, o_ng, o_fr, o_wi, o_mat, o_beta), stack)
    return nbad


@block
def _offset(offs, k):
    o_ok, o_p, o_ng, o_fr, o_wi, o_mat, o_beta = offs
    fr = ((o_fr[k, 0, 0], o_fr[k, 0, 1], o_fr[k, 0, 2]), (o_fr[k, 1, 0], o_fr[k, 1, 1], o_fr[k, 1, 2]),
          (o_fr[k, 2, 0], o_fr[k, 2, 1], o_fr[k, 2, 2]))
    return ((o_p[k, 0], o_p[k, 1], o_p[k, 2]), (o_ng[k, 0], o_ng[k, 1], o_ng[k, 2]), fr,
            (o_wi[k, 0], o_wi[k, 1], o_wi[k, 2]), o_mat[k], (o_beta[k, 0], o_beta[k, 1], o_beta[k, 2]))


@block
def _shift_photons(sa, lp, mtab, prm, out, hh, y, x, gp, r, cand, n, offs, stack):
    p, ng, frame, wi, mid, beta, state, m = gp
    ns, s, tt = frame
    mat = sa.materials[mid]
    o_ok = offs[0]
    nbad = 0
    cnt = 0
    for i in range(n):
        v = cand[i]
        if lp.depth[v] + m + 1 > prm.max_depth:
            continue
        if prm.filter_classes and not _class_ok(lp, v, state, prm.mask):
            continue
        if not parent_ok(lp, v, prm):
            continue
        cnt += 1
        wo_w = (-lp.d_in[v, 0], -lp.d_in[v, 1], -lp.d_in[v, 2])
        cg = abs(dot(wo_w, ng))
        if not cg > 1e-9:
            continue
        f = bsdf_eval(mat, wi, to_local(wo_w, s, tt, ns))
        c_b = (beta[0] * f[0] * lp.beta[v, 0] / cg, beta[1] * f[1] * lp.beta[v, 1] / cg,
               beta[2] * f[2] * lp.beta[v, 2] / cg)
        if not _finite3(c_b):
            nbad += 1
            continue
        _put(out.phi, hh, 0, y, x, c_b, 1.0)
        for k in range(4):
            status = FAILED
            term = (0.0, 0.0, 0.0)
            ratio = 0.0
            beta2 = (0.0, 0.0, 0.0)
            c_o = (0.0, 0.0, 0.0)
            if o_ok[k]:
                p2, ng2, fr2, wi2, mid2, beta2 = _offset(offs, k)
                status, term, ratio = shift_photon(sa, lp, mtab, prm, v, (p, frame), (p2, ng2, fr2, wi2, sa.materials[mid2]),
                                                   r, stack)
            if status != FAILED:
                c_o = (beta2[0] * term[0], beta2[1] * term[1], beta2[2] * term[2])
                if not (_finite3(c_o) and ratio > 0.0 and math.isfinite(ratio)):
                    status = FAILED
            out.count[hh, status, y, x] += 1
            if status == FAILED:
                _put(out.phi, hh, 1 + k, y, x, c_b, -1.0)
                continue
            wgt = mis_weight_from_log_ratio(math.log(ratio))
            _put(out.phi, hh, 1 + k, y, x, (c_o[0] - c_b[0], c_o[1] - c_b[1], c_o[2] - c_b[2]), wgt)
            _put(out.phi, hh, 5 + k, y, x, c_o, wgt)
    out.m[hh, y, x] = cnt
    return nbad
