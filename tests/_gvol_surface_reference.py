"""The surface pass of the volumetric full images (gvol_surface + gvol_surface_light at main 0ff81cb)
as it was before it shared GPM's fast photon loop: one photon at a time, its four shifts one after
the other, each a call of ``shift_surface_photon`` that finds the photon's parent, re-evaluates it
towards the base direction and walks the recorded edge again, and a buffer write per term. Kept as
the reference the shared loop must reproduce (recorded by tests/golden/passes.py, compared by
tests/test_photon_fast_passes.py). The row loop, the
per-photon loop and the light half of the shift are copied (with the helpers they took from
gpm_gather and gvpm_light); the camera paths, the walk through null interfaces, the medium segments
and the manifold walk are the package's own (camera_beams, gvol_surface_light.walk_to_surface and
_segment, gpm_light), which the rewrite leaves unchanged."""
import math

import numpy as np
from numba import prange

from gdlearn.kernels.accel.bvh import STACK_SIZE
from gdlearn.kernels import layout as L
from gdlearn.kernels.arrays import borrow, borrowed
from gdlearn.kernels.bsdf.dispatch import bsdf_eval, vertex_class
from gdlearn.kernels.camera import camera_ray
from gdlearn.kernels.geometry import INFO_MAT
from gdlearn.kernels.jit import block, rows
from gdlearn.kernels.media.medium import medium_params
from gdlearn.kernels.media.phase import hg_eval
from gdlearn.kernels.rng import path_state, rand_at
from gdlearn.kernels.vec import dot, to_local
from gdlearn.photons import grid as hashgrid
from gdlearn.photons.records import K_MEDIUM, K_SURFACE
from gdlearn.photons.trace import _borrow_rec
from gdlearn.integrators.photon.camera_beams import BEAM_COLS, MAX_BEAMS, beam_path
from gdlearn.integrators.photon.gather import _borrow_grid, _class_ok, parent_ok, pixel_angle, specular_vertex
from gdlearn.integrators.photon.gpm_gather import FAILED, MANIFOLD, RECONNECTED, GpmOut
from gdlearn.integrators.photon.gpm_light import _dir, parent_factor, same_point
from gdlearn.integrators.photon.photon_manifold import manifold_photon
from gdlearn.integrators.photon.gvol_surface_light import _segment, walk_to_surface
from gdlearn.integrators.photon.gvpm_light import FAIL, FAIL_SPECULAR, OK, _ancestor, _spawn
from gdlearn.shifts.mis import mis_weight_from_log_ratio
from gdlearn.shifts.photon import offset_target, photon_geometry_ratio, rotate
from gdlearn.shifts.replay import SHIFT_DX, SHIFT_DY

_ZERO = (0.0, 0.0, 0.0)


@block
def reference_rows(sa, lp, grids, mtab, prm, seed, sample0, radius, out):
    """gvol_surface.surface_rows as it was: every pixel's two base gather points and their shifts."""
    _surface_rows(borrowed(sa), _borrow_rec(lp), _borrow_grid(grids[0]), _borrow_grid(grids[1]), borrow(mtab), prm,
                  seed, sample0, radius, GpmOut(borrow(out.phi), borrow(out.le), borrow(out.m), borrow(out.foot),
                                                borrow(out.count), borrow(out.bad)))


@rows
def _surface_rows(sa, lp, ga, gb, mtab, prm, seed, sample0, radius, out):
    for y in prange(radius.shape[0]):
        out.bad[y] = _row(sa, lp, (ga, gb), mtab, prm, seed, sample0, radius, out, y)


@block
def _put(buf, hh, i, y, x, v, scale):
    for c in range(3):
        buf[hh, i, y, x, c] += scale * v[c]


@block
def _finite3(v):
    return np.isfinite(v[0]) and np.isfinite(v[1]) and np.isfinite(v[2])


@block
def _offset(offs, k):
    o_ok, o_p, o_ng, o_fr, o_wi, o_mat, o_beta = offs
    fr = ((o_fr[k, 0, 0], o_fr[k, 0, 1], o_fr[k, 0, 2]), (o_fr[k, 1, 0], o_fr[k, 1, 1], o_fr[k, 1, 2]),
          (o_fr[k, 2, 0], o_fr[k, 2, 1], o_fr[k, 2, 2]))
    return ((o_p[k, 0], o_p[k, 1], o_p[k, 2]), (o_ng[k, 0], o_ng[k, 1], o_ng[k, 2]), fr,
            (o_wi[k, 0], o_wi[k, 1], o_wi[k, 2]), o_mat[k], (o_beta[k, 0], o_beta[k, 1], o_beta[k, 2]))


@block
def _row(sa, lp, grids, mtab, prm, seed, sample0, radius, out, y):
    hgt, w = radius.shape
    cam = sa.camera
    nbad = 0
    stack = np.empty(STACK_SIZE, dtype=np.int32)
    cand = np.empty(4096, dtype=np.int64)
    beams = np.empty((MAX_BEAMS, BEAM_COLS))
    bstate = np.empty((MAX_BEAMS, 2), dtype=np.int64)
    offs = (np.zeros(4, dtype=np.bool_), np.zeros((4, 3)), np.zeros((4, 3)), np.zeros((4, 3, 3)), np.zeros((4, 3)),
            np.zeros(4, dtype=np.int64), np.zeros((4, 3)))
    for x in range(w):
        for hh in range(2):
            h = path_state(seed, y * w + x, sample0 + hh)
            fx = x + rand_at(h, 0)
            fy = y + rand_at(h, 1)
            o, d, _ = camera_ray(cam, fx, fy)
            ok, p, ng, frame, wi, mid, beta, state, m, dist, le, _ = beam_path(sa, prm, h, o, d, stack, beams, bstate)
            if _finite3(le):
                _put(out.le, hh, 0, y, x, le, 1.0)
            for k in range(4):
                _offset_path(sa, prm, h, fx, fy, x, y, w, hgt, k, stack, beams, bstate, (ok, state, m, le), offs,
                             out, hh)
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
            nbad += _shift_photons(sa, lp, mtab, prm, out, hh, y, x, (p, ng, frame, wi, mid, beta, state, m), r, cand,
                                   n, offs, stack)
    return nbad


@block
def _offset_path(sa, prm, h, fx, fy, x, y, w, hgt, k, stack, beams, bstate, base, offs, out, hh):
    ok, state, m, le = base
    o_ok, o_p, o_ng, o_fr, o_wi, o_mat, o_beta = offs
    o_ok[k] = False
    if not (0 <= x + SHIFT_DX[k] < w and 0 <= y + SHIFT_DY[k] < hgt):
        if _finite3(le):
            _put(out.le, hh, 1 + k, y, x, le, -1.0)
        return
    o2, d2, _ = camera_ray(sa.camera, fx + SHIFT_DX[k], fy + SHIFT_DY[k])
    ok2, p2, ng2, fr2, wi2, mid2, beta2, state2, m2, _, le2, _ = beam_path(sa, prm, h, o2, d2, stack, beams, bstate)
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
            ratio = 0.0
            c_o = (0.0, 0.0, 0.0)
            if o_ok[k]:
                p2, ng2, fr2, wi2, mid2, beta2 = _offset(offs, k)
                status, term, ratio = shift_surface_photon(sa, lp, mtab, prm, v, (p, frame),
                                                           (p2, ng2, fr2, wi2, sa.materials[mid2]), r, stack)
                c_o = (beta2[0] * term[0], beta2[1] * term[1], beta2[2] * term[2])
                if status != FAILED and not (_finite3(c_o) and ratio > 0.0 and math.isfinite(ratio)):
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
def _parent_ratio(sa, lp, q, v, w_new):
    one = (1.0, 1.0, 1.0)
    if lp.kind[q] == K_MEDIUM:
        g = medium_params(sa.media[lp.obj[q]])[2]
        w_old, _ = _dir((lp.pos[q, 0], lp.pos[q, 1], lp.pos[q, 2]), (lp.pos[v, 0], lp.pos[v, 1], lp.pos[v, 2]))
        wi = (-lp.d_in[q, 0], -lp.d_in[q, 1], -lp.d_in[q, 2])
        fb = hg_eval(g, wi[0] * w_old[0] + wi[1] * w_old[1] + wi[2] * w_old[2])
        fo = hg_eval(g, wi[0] * w_new[0] + wi[1] * w_new[1] + wi[2] * w_new[2])
        if not (fb > 0.0 and fo > 0.0):
            return FAIL, one, 0.0
        r = fo / fb
        return OK, (r, r, r), r
    status, fr, pr = parent_factor(sa, lp, q, v, w_new)
    if status == 2:
        return FAIL_SPECULAR, one, 0.0
    if status != 0:
        return FAIL, one, 0.0
    return OK, fr, pr


@block
def _vacuum_chain(lp, v):
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
    a = (lp.pos[q, 0], lp.pos[q, 1], lp.pos[q, 2])
    ys = (lp.pos[v, 0], lp.pos[v, 1], lp.pos[v, 2])
    if n_null == 0:
        return _segment(sa, lp.medium[v], a, ys, _ZERO, 0.0)
    w, _ = _dir(a, ys)
    ok, yb, _, _, n_b, tau, logp, med = walk_to_surface(sa, a, _spawn(lp, q, a, w), w, lp.medium[child], stack)
    return ok and n_b == n_null and med == lp.medium[v] and same_point(yb, ys, a, r), tau, logp


@block
def _reversible(sa, lp, q, child, ys, yh, ystar, p, frame, p2, frame2, r, stack):
    yq = (lp.pos[q, 0], lp.pos[q, 1], lp.pos[q, 2])
    if same_point(yh, ystar, yq, r):
        return True
    w, dl = _dir(yq, offset_target(yh, p2, frame2, p, frame))
    if not dl > 0.0:
        return False
    ok, yb, _, _, _, _, _, _ = walk_to_surface(sa, yq, _spawn(lp, q, yq, w), w, lp.medium[child], stack)
    return ok and same_point(yb, ys, yq, r)


@block
def reconnect_surface(sa, lp, prm, v, q, child, n_null, ystar, nstar, p2, r, stack):
    ys = (lp.pos[v, 0], lp.pos[v, 1], lp.pos[v, 2])
    yq = (lp.pos[q, 0], lp.pos[q, 1], lp.pos[q, 2])
    d, dl = _dir(yq, ystar)
    if not dl > 0.0:
        return FAIL, _ZERO, 0.0, d, ys
    status, fr, pr = _parent_ratio(sa, lp, q, v, d)
    if status != OK:
        return status, _ZERO, 0.0, d, ys
    ok, yh, _, prim, n_o, tau_o, logp_o, med = walk_to_surface(sa, yq, _spawn(lp, q, yq, d), d, lp.medium[child],
                                                               stack)
    if not (ok and n_o == n_null and med == lp.medium[v]):
        return FAIL, _ZERO, 0.0, d, ys
    if vertex_class(sa.materials[sa.prim_info[prim, INFO_MAT]], prm.threshold) == L.V_SPECULAR:
        return FAIL, _ZERO, 0.0, d, ys
    if not (yh[0] - p2[0]) ** 2 + (yh[1] - p2[1]) ** 2 + (yh[2] - p2[2]) ** 2 < r * r:
        return FAIL, _ZERO, 0.0, d, ys
    ok, tau_b, logp_b = _base_edge(sa, lp, q, child, n_null, v, r, stack)
    geo = photon_geometry_ratio(yq, ys, (lp.nrm[v, 0], lp.nrm[v, 1], lp.nrm[v, 2]), ystar, nstar)
    if not (ok and geo > 0.0):
        return FAIL, _ZERO, 0.0, d, ys
    f3 = (fr[0] * geo * math.exp(tau_b[0] - tau_o[0]), fr[1] * geo * math.exp(tau_b[1] - tau_o[1]),
          fr[2] * geo * math.exp(tau_b[2] - tau_o[2]))
    return OK, f3, pr * geo * math.exp(logp_o - logp_b), d, yh


@block
def shift_surface_photon(sa, lp, mtab, prm, v, base, off, r, stack):
    p, frame = base
    p2, ng2, frame2, wi2, mat2 = off
    q, child, n_null = _ancestor(sa, lp, v)
    if q < 0:
        return FAILED, _ZERO, 0.0
    ys = (lp.pos[v, 0], lp.pos[v, 1], lp.pos[v, 2])
    ystar = offset_target(ys, p, frame, p2, frame2)
    nstar = rotate((lp.nrm[v, 0], lp.nrm[v, 1], lp.nrm[v, 2]), frame, frame2)
    status, f3, ratio, d, yh = reconnect_surface(sa, lp, prm, v, q, child, n_null, ystar, nstar, p2, r, stack)
    if status == FAIL_SPECULAR and n_null == 0 and _vacuum_chain(lp, v):
        ok, ratio3, pp, w_arr = manifold_photon(sa, lp, mtab, prm, v, q, ystar, nstar, r, p2, stack)
        return _at_offset(MANIFOLD if ok else FAILED, lp, v, ratio3, pp, w_arr, off)
    if not (status == OK and _reversible(sa, lp, q, child, ys, yh, ystar, p, frame, p2, frame2, r, stack)):
        return FAILED, _ZERO, 0.0
    return _at_offset(RECONNECTED, lp, v, f3, ratio, d, off)
