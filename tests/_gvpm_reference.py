"""The G-VPM camera pass as it was before it was made fast (gvpm_gather at commit 6d8e429: one photon
at a time, its four shifts and their buffer writes one after the other; the reconnection walking the
recorded edge a -> b again for every neighbour): the straightforward reading of Gruson et al. 2018,
Sec. 4 and Eq. 19, kept here as the reference the fast kernel must reproduce bit for bit (recorded
by tests/golden/passes.py, compared by tests/test_photon_fast_passes.py). Only the per-photon loops
are copied; the camera paths, the distance copy and the light-path helpers are the package's own
(their results are unchanged by the rewrite)."""
import math

import numpy as np
from numba import prange

from gdlearn.kernels.accel.bvh import STACK_SIZE
from gdlearn.kernels.arrays import borrow, borrowed
from gdlearn.kernels.camera import camera_ray
from gdlearn.kernels.jit import block, rows
from gdlearn.kernels.media.medium import distance_pdf, medium_params, sample_distance_truncated_1, transmittance
from gdlearn.kernels.media.phase import hg_eval
from gdlearn.kernels.rng import path_state, rand_at
from gdlearn.photons.grid import query as grid_query
from gdlearn.photons.trace import _borrow_rec
from gdlearn.integrators.photon.camera_beams import BEAM_COLS, BEAM_D, BEAM_MED, BEAM_S, BEAM_W, MAX_BEAMS, beam_path
from gdlearn.integrators.photon.gather import _borrow_grid
from gdlearn.integrators.photon.photon_shift_loop import finite3 as _finite3, put as _put
from gdlearn.integrators.photon.gpm_light import _dir
from gdlearn.integrators.photon.gvpm_gather import (C_FAILED, C_MIXED, C_NULL, C_RECONNECTED, GvpmOut, _offset_gather,
                                                    _offset_path, _point)
from gdlearn.integrators.photon.gvpm_light import FAIL, OK, _ancestor, _parent_ratio, _spawn, edge_walk
from gdlearn.integrators.photon.volume_estimates import D_VOL, _admit, _pick_beam
from gdlearn.shifts.mis import mis_weight_from_log_ratio
from gdlearn.shifts.replay import SHIFT_DX, SHIFT_DY
from gdlearn.shifts.volume_photon import NULL, REFLECTED, photon_shift


@block
def reference_rows(sa, lp, grids, prm, gv, seed, sample0, radius, out):
    """Every pixel's two camera samples (sample0 + hh; half hh gathers grids[hh]) and their four shifts
    into ``out`` (a :class:`GvpmOut`); ``radius`` (H x W) is the kernel radius per pixel."""
    _gvpm_rows(borrowed(sa), _borrow_rec(lp), _borrow_grid(grids[0]), _borrow_grid(grids[1]), prm, gv, seed, sample0,
               radius, GvpmOut(borrow(out.phi), borrow(out.m), borrow(out.count), borrow(out.bad)))


@rows
def _gvpm_rows(sa, lp, ga, gb, prm, gv, seed, sample0, radius, out):
    for y in prange(radius.shape[0]):
        out.bad[y] = _row(sa, lp, (ga, gb), prm, gv, seed, sample0, radius, out, y)


@block
def _row(sa, lp, grids, prm, gv, seed, sample0, radius, out, y):
    hgt, w = radius.shape
    nbad = 0
    stack = np.empty(STACK_SIZE, dtype=np.int32)
    beams = np.empty((MAX_BEAMS, BEAM_COLS))
    bstate = np.empty((MAX_BEAMS, 2), dtype=np.int64)
    obeams = np.empty((4, MAX_BEAMS, BEAM_COLS))
    obstate = np.empty((4, MAX_BEAMS, 2), dtype=np.int64)
    o_ok = np.zeros(4, dtype=np.bool_)
    buf = np.empty(max(1, grids[0].order.shape[0], grids[1].order.shape[0]), dtype=np.int64)
    for x in range(w):
        for hh in range(2):
            h = path_state(seed, y * w + x, sample0 + hh)
            fx = x + rand_at(h, 0)
            fy = y + rand_at(h, 1)
            o, d, _ = camera_ray(sa.camera, fx, fy)
            nb = beam_path(sa, prm, h, o, d, stack, beams, bstate)[11]
            r = radius[y, x]
            if nb == 0 or not r > 0.0:
                continue
            for k in range(4):
                o_ok[k] = _offset_path(sa, prm, h, fx, fy, x + SHIFT_DX[k], y + SHIFT_DY[k], w, hgt, k, stack,
                                       beams, bstate, nb, obeams[k], obstate[k])
            nbad += _samples(sa, lp, grids[hh], prm, gv, h, (beams, bstate, nb), (obeams, o_ok), r, buf, stack,
                             out, hh, y, x)
    return nbad


@block
def _samples(sa, lp, grid, prm, gv, h, base, offs, r, buf, stack, out, hh, y, x):
    """VPM's K distance samples of one camera path, their photons and the photons' shifts."""
    beams, bstate, nb = base
    og = np.empty((4, 12))
    K = gv.samples
    cnt = 0
    nbad = 0
    for k in range(K):
        b, pb = _pick_beam(beams, nb, rand_at(h, D_VOL + 2 * k))
        if b < 0:
            break
        med = int(beams[b, BEAM_MED])
        sig, alb, g = medium_params(sa.media[med])
        sbar = (sig[0] + sig[1] + sig[2]) / 3.0
        if not sbar > 0.0:
            continue
        t, pdf = sample_distance_truncated_1(sbar, beams[b, BEAM_S], (k + rand_at(h, D_VOL + 2 * k + 1)) / K)
        if not pdf > 0.0:
            continue
        tr = transmittance(sig, t)
        k0 = 1.0 / (pdf * pb * K)
        cw = (beams[b, BEAM_W] * tr[0] * k0, beams[b, BEAM_W + 1] * tr[1] * k0, beams[b, BEAM_W + 2] * tr[2] * k0)
        _offset_gather(offs, nb, b, t, sbar, pb, pdf, tr, k0, og)
        dg = _point(beams, b, t)
        dc = (beams[b, BEAM_D], beams[b, BEAM_D + 1], beams[b, BEAM_D + 2])
        m, state = int(bstate[b, 1]), bstate[b, 0]
        for i in range(min(grid_query(grid, dg, r, buf), buf.shape[0])):
            v = buf[i]
            if not _admit(lp, v, prm, med, m, state):
                continue
            cnt += 1
            ph = hg_eval(g, dc[0] * lp.d_in[v, 0] + dc[1] * lp.d_in[v, 1] + dc[2] * lp.d_in[v, 2])
            c_b = (cw[0] * ph * lp.beta[v, 0], cw[1] * ph * lp.beta[v, 1], cw[2] * ph * lp.beta[v, 2])
            if not _finite3(c_b):
                nbad += 1
                continue
            _put(out.phi, hh, 0, y, x, c_b, 1.0)
            nbad += _shift_photon(sa, lp, v, dg, g, r, gv.mixed, og, c_b, stack, out, hh, y, x)
    out.m[hh, y, x] = cnt
    return nbad


@block
def _shift_photon(sa, lp, v, dg, g, r, mixed, og, c_b, stack, out, hh, y, x):
    """Photon row v (base term c_b) shifted to the four offset gather points og: D_k, S_k, counts."""
    nbad = 0
    bpos = (lp.pos[v, 0], lp.pos[v, 1], lp.pos[v, 2])
    for j in range(4):
        c_o = (0.0, 0.0, 0.0)
        ratio = 0.0
        kind = NULL
        ok = og[j, 0] > 0.0
        if ok:
            dp = (og[j, 1], og[j, 2], og[j, 3])
            b2, kind = photon_shift(bpos, dg, dp, r, mixed)
            f3, rl, w_in = (1.0, 1.0, 1.0), 1.0, (lp.d_in[v, 0], lp.d_in[v, 1], lp.d_in[v, 2])
            if kind != NULL:
                status, f3, rl, w_in = _reconnect(sa, lp, v, b2, stack)
                ok = status == OK
            if ok:
                ph = hg_eval(g, og[j, 4] * w_in[0] + og[j, 5] * w_in[1] + og[j, 6] * w_in[2])
                c_o = (og[j, 7] * ph * lp.beta[v, 0] * f3[0], og[j, 8] * ph * lp.beta[v, 1] * f3[1],
                       og[j, 9] * ph * lp.beta[v, 2] * f3[2])
                ratio = og[j, 10] * rl
                if not (_finite3(c_o) and math.isfinite(ratio)):
                    nbad += 1                                  # counted, never written
                    ok = False
                elif not ratio > 0.0:
                    ok = False
            if ok:
                out.count[hh, C_NULL if kind == NULL else C_RECONNECTED, y, x] += 1
                if kind == REFLECTED:
                    out.count[hh, C_MIXED, y, x] += 1
        if not ok:
            out.count[hh, C_FAILED, y, x] += 1
            _put(out.phi, hh, 1 + j, y, x, c_b, -1.0)          # w = 1, no offset (PHOTONS.md Sec. 0.2)
            continue
        # Eq. 19, balance heuristic (a null shift's: the camera side's, og[j, 11])
        wgt = og[j, 11] if kind == NULL else mis_weight_from_log_ratio(math.log(ratio))
        _put(out.phi, hh, 1 + j, y, x, (c_o[0] - c_b[0], c_o[1] - c_b[1], c_o[2] - c_b[2]), wgt)
        _put(out.phi, hh, 5 + j, y, x, c_o, wgt)
    return nbad


@block
def _reconnect(sa, lp, v, b_off, stack):
    """Reconnect photon row v's parent to the offset photon ``b_off`` (module docstring). Returns
    (status, beta_b' / beta_b per channel, light-side density ratio p(b' | a) / p(b | a), the
    direction a -> b' the offset photon arrives along)."""
    zero = (0.0, 0.0, 0.0)
    q, child, n_null = _ancestor(sa, lp, v)
    if q < 0:
        return FAIL, zero, 0.0, zero
    a = (lp.pos[q, 0], lp.pos[q, 1], lp.pos[q, 2])
    b = (lp.pos[v, 0], lp.pos[v, 1], lp.pos[v, 2])
    w_new, l_new = _dir(a, b_off)
    w_old, l_old = _dir(a, b)
    if not (l_new > 0.0 and l_old > 0.0):
        return FAIL, zero, 0.0, zero
    status, fr, pr = _parent_ratio(sa, lp, q, v, w_new)
    if status != OK:
        return status, zero, 0.0, zero
    start = lp.medium[child]
    ok, n_o, tau_o, logp_o, med_o = edge_walk(sa, a, _spawn(lp, q, a, w_new), w_new, b_off, start, stack)
    if not (ok and n_o == n_null and med_o == lp.medium[v]):
        return FAIL, zero, 0.0, zero
    if n_null == 0:
        # a recorded edge crosses no surface: its optical depth and density need no ray
        sig = medium_params(sa.media[lp.medium[v]])[0]
        pc = distance_pdf(sig, l_old)
        if not pc > 0.0:
            return FAIL, zero, 0.0, zero
        tau_b, logp_b = (sig[0] * l_old, sig[1] * l_old, sig[2] * l_old), math.log(pc)
    else:
        ok, n_b, tau_b, logp_b, med_b = edge_walk(sa, a, _spawn(lp, q, a, w_old), w_old, b, start, stack)
        if not (ok and n_b == n_null and med_b == lp.medium[v]):
            return FAIL, zero, 0.0, zero
    geo = (l_old * l_old) / (l_new * l_new)
    # T(a, b') / T(a, b) = exp(-(tau' - tau)) per channel: one exponential, no 0 / 0 in a dense medium
    f3 = (fr[0] * math.exp(tau_b[0] - tau_o[0]) * geo, fr[1] * math.exp(tau_b[1] - tau_o[1]) * geo,
          fr[2] * math.exp(tau_b[2] - tau_o[2]) * geo)
    return OK, f3, pr * math.exp(logp_o - logp_b) * geo, w_new
