"""The G-BRE camera pass as it was before it was made fast (gbre_gather at commit 0ff81cb: one photon at
a time, its four shifts and their buffer writes one after the other through non-inlined calls; every
neighbour's reconnection walking the photon's recorded edge a -> b again, ``gvpm_light.reconnect``):
the straightforward reading of Gruson et al. 2018, Sec. 5.1 and Eq. 19, kept here as the reference
the fast kernel must reproduce bit for bit (recorded by tests/golden/passes.py, compared by
tests/test_photon_fast_passes.py). The whole module is copied
(shift_3d / shift_2d included); the camera paths, the BRE's kernel, the photon shifts and the
light-path helpers are the package's own (the rewrite leaves their arithmetic unchanged)."""
from __future__ import annotations

import math
import numpy as np
from numba import prange

from gdlearn.kernels.accel.bvh import STACK_SIZE
from gdlearn.kernels.arrays import borrow, borrowed
from gdlearn.kernels.camera import camera_ray
from gdlearn.kernels.jit import block, rows
from gdlearn.kernels.media.medium import medium_params, transmittance
from gdlearn.kernels.media.phase import hg_eval
from gdlearn.kernels.rng import path_state, rand_at
from gdlearn.photons import bbh as bbh_mod
from gdlearn.photons.trace import _borrow_rec
from gdlearn.integrators.photon.camera_beams import BEAM_COLS, BEAM_D, BEAM_MED, BEAM_O, BEAM_S, BEAM_W, MAX_BEAMS, \
    beam_path
from gdlearn.integrators.photon.photon_shift_loop import finite3 as _finite3, put as _put
from gdlearn.integrators.photon.gvpm_gather import C_FAILED, C_MIXED, C_NULL, C_RECONNECTED, GvpmOut, _offset_path
from gdlearn.integrators.photon.gvpm_light import OK, reconnect
from gdlearn.integrators.photon.volume_estimates import KERNEL_2D, _admit, beam_kernel
from gdlearn.shifts.mis import mis_weight_from_log_ratio
from gdlearn.shifts.replay import SHIFT_DX, SHIFT_DY
from gdlearn.shifts.volume_photon import NULL, REFLECTED, TRANSLATED, camera_distance_copy, chord_half, \
    photon_shift, ray_frame_copy


_ZERO = (0.0, 0.0, 0.0)
_ONE = (1.0, 1.0, 1.0)


@block
def _along(o, d, t):
    return (o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2])


@block
def shift_3d(sa, lp, v, o, d, o_off, d_off, t, s_off, r, mixed, stack):
    """G-BRE-3D's shift of photon row v gathered at d = o + t d on the base beam, to the offset beam
    (o', d', length s'): (ok, kind, beta_b' / beta_b per channel, offset over base density ratio
    of Eq. 19, the direction the offset photon arrives along). Module docstring, item 4."""
    if not camera_distance_copy(t, s_off)[0]:
        return False, NULL, _ONE, 0.0, _ZERO
    b = (lp.pos[v, 0], lp.pos[v, 1], lp.pos[v, 2])
    dg, dp = _along(o, d, t), _along(o_off, d_off, t)
    half = chord_half(r, bbh_mod.perp(o, d, b)[1])
    b2, kind = photon_shift(b, dg, dp, r, mixed)
    e = (b2[0] - dp[0], b2[1] - dp[1], b2[2] - dp[2])
    half2 = chord_half(r, bbh_mod.perp(o_off, d_off, b2)[1])
    if not (e[0] * e[0] + e[1] * e[1] + e[2] * e[2] < r * r and half2 > 0.0 and half > 0.0):
        return False, kind, _ONE, 0.0, _ZERO       # b' on K''s boundary: a null set, its reverse weighs 0
    if kind == NULL:
        return True, kind, _ONE, half / half2, (lp.d_in[v, 0], lp.d_in[v, 1], lp.d_in[v, 2])
    status, f3, rl, w_in = reconnect(sa, lp, v, b2, stack)
    if status != OK:
        return False, kind, _ONE, 0.0, _ZERO
    return True, kind, f3, rl * half / half2, w_in


@block
def shift_2d(sa, lp, v, o, d, o_off, d_off, t, s_off, stack):
    """G-BRE-2D's shift of photon row v (its projection on the base beam at t) by the ray-frame copy,
    then the reconnection from its parent; returns as :func:`shift_3d` (kind TRANSLATED)."""
    if not camera_distance_copy(t, s_off)[0]:
        return False, TRANSLATED, _ONE, 0.0, _ZERO
    b = (lp.pos[v, 0], lp.pos[v, 1], lp.pos[v, 2])
    ok, b2 = ray_frame_copy(b, _along(o, d, t), d, _along(o_off, d_off, t), d_off)
    if not ok:
        return False, TRANSLATED, _ONE, 0.0, _ZERO
    status, f3, rl, w_in = reconnect(sa, lp, v, b2, stack)
    if status != OK:
        return False, TRANSLATED, _ONE, 0.0, _ZERO
    return True, TRANSLATED, f3, rl, w_in


@block
def reference_rows(sa, lp, bbhs, r, prm, gp, wsub, seed, sample0, out):
    """Every pixel's two camera samples (sample0 + hh) and their four shifts into ``out`` (a
    :class:`~gdlearn.integrators.photon.gvpm_gather.GvpmOut`); ``bbhs`` holds four hierarchies, (half 0, parity 0), (0, 1), (1, 0), (1, 1)
    -- without subsets each half's twice --, ``r`` is the pass's global radius, ``wsub`` (2 x 2) the
    subset weights per half and parity."""
    _gbre_rows(borrowed(sa), _borrow_rec(lp), bbhs[0], bbhs[1], bbhs[2], bbhs[3], r, prm, gp, wsub, seed, sample0,
               GvpmOut(borrow(out.phi), borrow(out.m), borrow(out.count), borrow(out.bad)))


@rows
def _gbre_rows(sa, lp, b00, b01, b10, b11, r, prm, gp, wsub, seed, sample0, out):
    for row in prange(out.bad.shape[0]):
        y = np.int64(row)
        out.bad[y] = _row(sa, lp, (b00, b01, b10, b11), r, prm, gp, wsub, seed, sample0, out, y)


@block
def _row(sa, lp, bbhs, r, prm, gp, wsub, seed, sample0, out, y):
    hgt, w = out.m.shape[1], out.m.shape[2]
    nbad = 0
    stack = np.empty(STACK_SIZE, dtype=np.int32)
    beams = np.empty((MAX_BEAMS, BEAM_COLS))
    bstate = np.empty((MAX_BEAMS, 2), dtype=np.int64)
    obeams = np.empty((4, MAX_BEAMS, BEAM_COLS))
    obstate = np.empty((4, MAX_BEAMS, 2), dtype=np.int64)
    o_ok = np.zeros(4, dtype=np.bool_)
    nmax = 1
    for i in range(4):
        nmax = max(nmax, bbhs[i].order.shape[0])
    buf = np.empty(nmax, dtype=np.int64)
    for x in range(w):
        par = (x + y) & 1 if gp.subsets else 0
        for hh in range(2):
            h = path_state(seed, y * w + x, sample0 + hh)
            fx = x + rand_at(h, 0)
            fy = y + rand_at(h, 1)
            o, d, _ = camera_ray(sa.camera, fx, fy)
            nb = beam_path(sa, prm, h, o, d, stack, beams, bstate)[11]
            if nb == 0:
                continue
            for k in range(4):
                o_ok[k] = _offset_path(sa, prm, h, fx, fy, x + SHIFT_DX[k], y + SHIFT_DY[k], w, hgt, k, stack,
                                       beams, bstate, nb, obeams[k], obstate[k])
            cnt = 0
            for b in range(nb):
                c, bad = _beam(sa, lp, bbhs[2 * hh + par], prm, gp, h, (beams, bstate, b), (obeams, o_ok), r,
                               wsub[hh, par], buf, stack, out, hh, y, x)
                cnt += c
                nbad += bad
            out.m[hh, y, x] = cnt
    return nbad


@block
def _beam(sa, lp, bbh, prm, gp, h, base, offs, r, ws, buf, stack, out, hh, y, x):
    """The BRE along beam b (bre_beam's photons, kernel and random numbers) and every photon's four
    shifts: (photons counted, non-finite terms dropped)."""
    beams, bstate, b = base
    med = int(beams[b, BEAM_MED])
    sig, alb, g = medium_params(sa.media[med])
    oa = np.empty(3)
    da = np.empty(3)
    for c in range(3):
        oa[c] = beams[b, BEAM_O + c]
        da[c] = beams[b, BEAM_D + c]
    o = (oa[0], oa[1], oa[2])
    d = (da[0], da[1], da[2])
    s = beams[b, BEAM_S]
    m = int(bstate[b, 1])
    state = bstate[b, 0]
    n = bbh_mod.collect(bbh, oa, da, s, gp.kernel, buf)
    cnt = 0
    nbad = 0
    for i in range(min(n, buf.shape[0])):
        v = buf[i]
        if not _admit(lp, v, prm, med, m, state):
            continue
        tp, dp2 = bbh_mod.perp(o, d, (lp.pos[v, 0], lp.pos[v, 1], lp.pos[v, 2]))
        ok, t, kw = beam_kernel(gp.kernel, r, s, tp, dp2, h, b, v)     # the BRE's own kernel and chord point
        if not ok:
            continue
        cnt += 1
        tr = transmittance(sig, t)
        ph = hg_eval(g, d[0] * lp.d_in[v, 0] + d[1] * lp.d_in[v, 1] + d[2] * lp.d_in[v, 2]) * kw
        c_b = (beams[b, BEAM_W] * (ph * tr[0] * lp.beta[v, 0]) * ws,
               beams[b, BEAM_W + 1] * (ph * tr[1] * lp.beta[v, 1]) * ws,
               beams[b, BEAM_W + 2] * (ph * tr[2] * lp.beta[v, 2]) * ws)
        if not _finite3(c_b):
            nbad += 1
            continue
        _put(out.phi, hh, 0, y, x, c_b, 1.0)
        pre = (tr[0] * lp.beta[v, 0] * kw * ws, tr[1] * lp.beta[v, 1] * kw * ws, tr[2] * lp.beta[v, 2] * kw * ws)
        nbad += _shift_photon(sa, lp, v, gp, g, (o, d, b, t, r), offs, pre, c_b, stack, out, hh, y, x)
    return cnt, nbad


@block
def _shift_photon(sa, lp, v, gp, g, q, offs, pre, c_b, stack, out, hh, y, x):
    """Photon row v (base term c_b; ``pre`` = T(t) beta kernel weight, per channel) shifted to the
    four offset beams: D_k, S_k and the counts."""
    o, d, b, t, r = q
    obeams, o_ok = offs
    nbad = 0
    for j in range(4):
        ok = o_ok[j]
        kind = NULL
        c_o = _ZERO
        ratio = 0.0
        if ok:
            ob = obeams[j]
            o2 = (ob[b, BEAM_O], ob[b, BEAM_O + 1], ob[b, BEAM_O + 2])
            d2 = (ob[b, BEAM_D], ob[b, BEAM_D + 1], ob[b, BEAM_D + 2])
            if gp.kernel == KERNEL_2D:
                ok, kind, f3, ratio, w_in = shift_2d(sa, lp, v, o, d, o2, d2, t, ob[b, BEAM_S], stack)
            else:
                ok, kind, f3, ratio, w_in = shift_3d(sa, lp, v, o, d, o2, d2, t, ob[b, BEAM_S], r, gp.mixed, stack)
            if ok:
                # f(T x) |J| / p(x): the offset camera weight, the phase at d' for the (new) arrival
                # direction, the base's T(t) (same t, same medium) and the base's kernel density
                ph = hg_eval(g, d2[0] * w_in[0] + d2[1] * w_in[1] + d2[2] * w_in[2])
                c_o = (ob[b, BEAM_W] * ph * pre[0] * f3[0], ob[b, BEAM_W + 1] * ph * pre[1] * f3[1],
                       ob[b, BEAM_W + 2] * ph * pre[2] * f3[2])
                if not (_finite3(c_o) and math.isfinite(ratio)):
                    nbad += 1
                    ok = False
                elif not ratio > 0.0:
                    ok = False
        if not ok:
            out.count[hh, C_FAILED, y, x] += 1
            _put(out.phi, hh, 1 + j, y, x, c_b, -1.0)          # w = 1, no offset (PHOTONS.md Sec. 0.2)
            continue
        out.count[hh, C_NULL if kind == NULL else C_RECONNECTED, y, x] += 1
        if kind == REFLECTED:
            out.count[hh, C_MIXED, y, x] += 1
        wgt = mis_weight_from_log_ratio(math.log(ratio))      # Eq. 19, balance heuristic
        _put(out.phi, hh, 1 + j, y, x, (c_o[0] - c_b[0], c_o[1] - c_b[1], c_o[2] - c_b[2]), wgt)
        _put(out.phi, hh, 5 + j, y, x, c_o, wgt)
    return nbad
