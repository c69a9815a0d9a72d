"""The camera pass of gradient-domain volumetric photon mapping, G-VPM (Gruson et al. 2018, Sec. 4;
PHOTONS.md Sec. 5.5), light transport ending in the medium.

Per pixel and half (camera sample 2 i + hh of pass i, as :mod:`gdlearn.integrators.photon.volume_gather`):

1. **Base**: the camera path with long beams (:func:`gdlearn.integrators.photon.camera_beams.beam_path`)
   and VPM's K stratified distance samples on its beams (the same random dimensions as
   :func:`gdlearn.integrators.photon.volume_estimates.vpm_beam`, so the base buffer *is* VPM's medium
   estimate): beam b with probability P(b), the gather point d at distance t ~ p(t) on it, every
   volume photon in Ball(d, R).
2. **Offset camera subpaths** (once per camera sample): the path re-traced from the neighbour's film
   position (the base position +-1 pixel, the sub-pixel offset kept) with the base's random numbers,
   as GPM does (:mod:`gdlearn.integrators.photon.gpm_gather`): the random-replay shift, whose camera
   prefix weight is the offset's own f / p and whose prefix density ratio is 1. It must have the
   base's structure -- as many beams, each in the same medium after the same surface vertices of
   the same classes -- or the shift fails (a symmetric rule). A neighbour outside the image is a
   failed shift (PHOTONS.md E12).
3. **Camera distance copy** (Eq. 14-15, :func:`gdlearn.shifts.volume_photon.camera_distance_copy`):
   d' = c' + t w'_c on the offset's beam b; fails where that beam is shorter than t.
4. **Photon shift** (Eq. 16, mixed by default; ``simple``: every photon translated), then the light
   subpath: unchanged for a null-shifted photon (T(y) = y), else reconnected from its parent
   (:func:`gdlearn.integrators.photon.gvpm_light.reconnect`), or -- a specular parent -- completed by
   the manifold walk (Sec. 4.3, :mod:`gdlearn.integrators.photon.photon_manifold`).
5. **MIS** (Eq. 19, balance heuristic in ratio form, :func:`gdlearn.shifts.mis.mis_weight_from_log_ratio`):
   the offset over base density ratio is the camera side's ``[P'(b) p'(t)] / [P(b) p(t)]`` -- the
   offset's own beam-selection probability and its truncated-exponential density on its own beam,
   the densities the offset pixel samples with (PHOTONS.md E10) -- times the light side's (1 for a
   null shift). (The reference code's base selection probability for the offset cancels in the
   ratio, each way, so its weights are complementary too: E10 makes them the balance heuristic
   proper, not unbiased where they were not.) The offset contribution itself uses the base's
   densities (f(T x) ``|J|`` / p(x), ``|J|`` = 1).

Organisation (for speed; benchmarks/README.md, G-VPM section): a distance sample's photons are
collected once (row and base term, per-row scratch), then shifted photon by photon to the four
neighbours, D_k, S_k and counts summed in a row scratch in photon order -- the buffers are bit for
bit those of one write per photon and shift (tests/_gvpm_reference.py, recorded by
tests/golden/passes.py, compared by tests/test_photon_fast_passes.py) --; a photon's recorded edge a -> b
is walked once for the four neighbours (``gvpm_light.base_edge``), and so is the specular chain
above it built once (``photon_manifold.volume_chain``); the offset camera paths are traced only for
a camera sample whose distance samples find a photon.

Buffers (:mod:`gdlearn.integrators.gradients`), per half and base pixel: L (index 0), D_k (1 + k),
S_k (5 + k), k = right, left, down, up, each without the kernel's 1 / V(R) (the caller divides, as
VPM does); ``count`` the photon shifts: null (b' = b), mixed (reflected by Eq. 16; they are also
counted as reconnected or walked), reconnected (a light subpath completed from the photon's parent),
failed (camera or light side), manifold (completed by the walk of a specular chain above the parent,
:func:`gdlearn.integrators.photon.photon_manifold.manifold_volume_photon`).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from gdlearn.kernels.accel.bvh import STACK_SIZE
from gdlearn.kernels.arrays import borrow, borrowed
from gdlearn.kernels.camera import camera_ray
from gdlearn.kernels.jit import block, inlined, ir_inline
from gdlearn.kernels.media.medium import medium_params, sample_distance_truncated_1, transmittance
from gdlearn.kernels.media.phase import hg_eval
from gdlearn.kernels.rng import path_state, rand_at
from gdlearn.kernels.threads import next_rows, run_rows
from gdlearn.photons.grid import query as grid_query
from gdlearn.photons.trace import _borrow_rec
from gdlearn.integrators.photon.camera_beams import BEAM_COLS, BEAM_D, BEAM_MED, BEAM_O, BEAM_S, BEAM_W, MAX_BEAMS, \
    beam_path
from gdlearn.integrators.photon.gather import _borrow_grid
from gdlearn.integrators.photon.gvpm_light import EDGE_COLS, EDGE_UNKNOWN, OK, base_edge, load_edge, store_edge
from gdlearn.integrators.photon.photon_manifold import CHAIN_UNKNOWN, VolumeChain, complete_volume_photon, \
    new_volume_chain
from gdlearn.integrators.photon.volume_estimates import D_VOL, _admit, _pick_beam, beam_weight
from gdlearn.shifts.mis import mis_weight_from_log_ratio
from gdlearn.shifts.replay import SHIFT_DX, SHIFT_DY
from gdlearn.shifts.volume_photon import NULL, REFLECTED, camera_distance_copy, photon_shift, truncated_distance_pdf

#: GvpmOut.count[:, i]: null-shifted, mixed (reflected), reconnected, failed photon shifts, and those
#: completed by the manifold walk (a specular parent)
C_NULL, C_MIXED, C_RECONNECTED, C_FAILED, C_MANIFOLD = 0, 1, 2, 3, 4
N_COUNTS = 5


class GvpmParams(NamedTuple):
    samples: int          # distance samples per camera path (VPM's K)
    mixed: bool           # the mixed shift (Eq. 16); False: the simple shift (a translation)
    relaxed: bool         # the relaxed manifold walk (Sec. 6.1; photon_manifold.shift_volume_chain); False: exact


class GvpmOut(NamedTuple):
    phi: np.ndarray       # (2, 9, H, W, 3): L, D_k, S_k of the medium terms, without 1 / V(R)
    m: np.ndarray         # (2, H, W): photons the base gather points found (SPPM's M)
    count: np.ndarray     # (2, 5, H, W): photon shifts null / mixed / reconnected / failed / manifold
    bad: np.ndarray       # (H,): non-finite terms dropped


class Scratch(NamedTuple):
    """A row's scratch arrays, allocated once per row (numba would allocate them per call otherwise)."""
    buf: np.ndarray       # the hash grid's candidates (as many as it has points)
    og: np.ndarray        # (4, 12): the four offset gather points of the current distance sample
    rows: np.ndarray      # one distance sample's admitted photons (light-vertex rows; -1: dropped)
    cb: np.ndarray        # (n, 3): their base terms c_b
    edge: np.ndarray      # (n, EDGE_COLS): their recorded edges a -> b, computed once for all neighbours
    acc: np.ndarray       # (9, 3): a distance sample's D_j (rows 1 + j) and S_j (5 + j), as the buffers (row 0
                          # unused: L is summed by _collect), summed in photon order
    cnt: np.ndarray       # (N_COUNTS,) int64: its shift counts
    chain: VolumeChain    # the current photon's specular chain, built once for its four neighbours


def allocate(h: int, w: int) -> GvpmOut:
    return GvpmOut(np.zeros((2, 9, h, w, 3)), np.zeros((2, h, w)), np.zeros((2, N_COUNTS, h, w)), np.zeros(h, np.int64))


def gvpm_rows(sa, lp, grids, mtab, prm, gv, seed, sample0, radius, out):
    """Every pixel's two camera samples (sample0 + hh; half hh gathers grids[hh]) and their four shifts
    into ``out`` (a :class:`GvpmOut`); ``radius`` (H x W) is the kernel radius per pixel, ``mtab`` the
    specular shapes the manifold walk moves (``gpt_surface.manifold.manifold_table``). The rows run
    on threads (``kernels.threads.run_rows``), and the steps below the row driver are IR-inlined into
    it, for the cold compile (:func:`gdlearn.integrators.photon.gbre_gather.gbre_rows` says why)."""
    run_rows(lambda counter, step: _gvpm_rows(sa, lp, grids[0], grids[1], mtab, prm, gv, seed, sample0, radius, out,
                                              counter, step), radius.shape[0])


@block(nogil=True)
def _gvpm_rows(sa, lp, ga, gb, mtab, prm, gv, seed, sample0, radius, out, counter, step):
    """One thread's share of :func:`gvpm_rows`: chunks of ``step`` rows taken from ``counter``."""
    # borrowed views: no atomic reference counts shared by the threads (kernels.arrays.borrow)
    sb, lb, grids = borrowed(sa), _borrow_rec(lp), (_borrow_grid(ga), _borrow_grid(gb))
    ob = GvpmOut(borrow(out.phi), borrow(out.m), borrow(out.count), borrow(out.bad))
    h = radius.shape[0]
    while True:
        y0, y1 = next_rows(counter, step, h)
        if y0 == y1:
            return
        for y in range(y0, y1):
            ob.bad[y] = _row(sb, lb, grids, mtab, prm, gv, seed, sample0, radius, ob, y)


@ir_inline
def _row(sa, lp, grids, mtab, prm, gv, seed, sample0, radius, out, y):
    hgt, w = radius.shape
    nbad = 0
    stack = np.empty(STACK_SIZE, dtype=np.int32)
    beams = np.empty((MAX_BEAMS, BEAM_COLS))
    bstate = np.empty((MAX_BEAMS, 2), dtype=np.int64)
    obeams = np.empty((4, MAX_BEAMS, BEAM_COLS))
    obstate = np.empty((4, MAX_BEAMS, 2), dtype=np.int64)
    o_ok = np.zeros(4, dtype=np.bool_)
    nbuf = max(1, grids[0].order.shape[0], grids[1].order.shape[0])
    # per-row scratch, allocated once (not per sample): the grid's candidates, then one distance
    # sample's admitted photons (row, base term) and their recorded edges (gvpm_light.base_edge)
    scr = Scratch(np.empty(nbuf, dtype=np.int64), np.empty((4, 12)), np.empty(nbuf, dtype=np.int64),
                  np.empty((nbuf, 3)), np.empty((nbuf, EDGE_COLS)), np.empty((9, 3)),
                  np.empty(N_COUNTS, dtype=np.int64), new_volume_chain())
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
            nbad += _samples(sa, lp, grids[hh], mtab, prm, gv, h, (beams, bstate, nb), (obeams, obstate, o_ok),
                             (fx, fy, x, y, w, hgt), r, scr, stack, out, hh, y, x)
    return nbad


@inlined
def offset_paths(sa, prm, h, film, stack, beams, bstate, nb, offs):
    """The four neighbours' offset camera paths of a camera sample (step 2 of the module docstring;
    G-BRE's camera pass too): ``film`` = (fx, fy, x, y, width, height), ``offs`` = (obeams,
    obstate, o_ok), filled. Callers trace them at the sample's first photon: they depend on the
    sample's random numbers alone, so the buffers are those of tracing them first."""
    fx, fy, x, y, w, hgt = film
    obeams, obstate, o_ok = offs
    for k in range(4):
        o_ok[k] = _offset_path(sa, prm, h, fx, fy, x + SHIFT_DX[k], y + SHIFT_DY[k], w, hgt, k, stack, beams, bstate,
                               nb, obeams[k], obstate[k])


@block
def _offset_path(sa, prm, h, fx, fy, xo, yo, w, hgt, k, stack, beams, bstate, nb, ob, obs):
    """Trace neighbour k's offset camera path (random replay from the film position +-1 pixel) into
    ``ob``/``obs``; does it have the base's structure (beam count, media, classes)?"""
    if not (0 <= xo < w and 0 <= yo < hgt):
        return False                              # outside the image: a failed shift (E12)
    o2, d2, _ = camera_ray(sa.camera, fx + SHIFT_DX[k], fy + SHIFT_DY[k])
    nb2 = beam_path(sa, prm, h, o2, d2, stack, ob, obs)[11]
    if nb2 != nb:
        return False
    for i in range(nb):
        if ob[i, BEAM_MED] != beams[i, BEAM_MED] or obs[i, 0] != bstate[i, 0] or obs[i, 1] != bstate[i, 1]:
            return False
    return True


@block
def _beam_prob(beams, nb, b):
    """P(b) of :func:`gdlearn.integrators.photon.volume_estimates._pick_beam` (max-component weights)."""
    tot = 0.0
    for i in range(nb):
        tot += beam_weight(beams, i)
    if not tot > 0.0:
        return 0.0
    return beam_weight(beams, b) / tot


@block
def _point(beams, b, t):
    return (beams[b, BEAM_O] + t * beams[b, BEAM_D], beams[b, BEAM_O + 1] + t * beams[b, BEAM_D + 1],
            beams[b, BEAM_O + 2] + t * beams[b, BEAM_D + 2])


@block
def _offset_gather(offs, nb, b, t, sbar, pb, pdf, tr, k0, og):
    """The distance copy onto every neighbour's beam b: og[j] = (ok, d' (3), w'_c (3), camera factor
    W' T(t) k0 (3), camera-side density ratio P'(b) p'(t) / (P(b) p(t)), the MIS weight of a null
    shift -- which depends on the camera side only, so it is computed once per sample and neighbour)."""
    obeams, o_ok = offs
    for j in range(4):
        og[j, 0] = 0.0
        if not o_ok[j]:
            continue
        ob = obeams[j]
        if not camera_distance_copy(t, ob[b, BEAM_S])[0]:
            continue                          # the offset's beam is shorter than t (Eq. 15's failure)
        ratio = _beam_prob(ob, nb, b) * truncated_distance_pdf(sbar, ob[b, BEAM_S], t) / (pb * pdf)
        if not (ratio > 0.0 and math.isfinite(ratio)):
            continue
        p = _point(ob, b, t)
        og[j, 0] = 1.0
        for c in range(3):
            og[j, 1 + c] = p[c]
            og[j, 4 + c] = ob[b, BEAM_D + c]
            og[j, 7 + c] = ob[b, BEAM_W + c] * tr[c] * k0
        og[j, 10] = ratio
        og[j, 11] = mis_weight_from_log_ratio(math.log(ratio))


@ir_inline
def _samples(sa, lp, grid, mtab, prm, gv, h, base, offs, film, r, scr, stack, out, hh, y, x):
    """VPM's K distance samples of one camera path, their photons and the photons' shifts. The
    offset camera paths and gather points are made only when a distance sample finds a photon:
    at gvpm's small kernel most find none (on the spot light and the volume caustic, 69-74 % of
    the pixels found none with either of their two camera samples)."""
    beams, bstate, nb = base
    og = scr.og
    K = gv.samples
    cnt = 0
    nbad = 0
    traced = False
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
        dg = _point(beams, b, t)
        dc = (beams[b, BEAM_D], beams[b, BEAM_D + 1], beams[b, BEAM_D + 2])
        n, nbad0 = _collect(lp, grid, prm, (med, int(bstate[b, 1]), bstate[b, 0]), g, dg, dc, cw, r, scr, out, hh, y, x)
        cnt += n
        nbad += nbad0
        if n == 0:
            continue                  # no photon to shift: D_k, S_k and the counts would not change
        if not traced:
            offset_paths(sa, prm, h, film, stack, beams, bstate, nb, offs)
            traced = True
        _offset_gather((offs[0], offs[2]), nb, b, t, sbar, pb, pdf, tr, k0, og)
        nbad += _shift_photons(sa, lp, mtab, scr, n, dg, g, r, gv, og, stack, out, hh, y, x)
    out.m[hh, y, x] = cnt
    return nbad


@inlined
def _finite(a, b, c):
    return math.isfinite(a) and math.isfinite(b) and math.isfinite(c)


@ir_inline
def _collect(lp, grid, prm, where, g, dg, dc, cw, r, scr, out, hh, y, x):
    """The base: every admitted photon in Ball(dg, r), its term c_b = camera factor x rho x beta added
    to L (in a register, in photon order: the buffer's sum is the same as one write per photon) and
    kept with its row in the scratch for the four neighbours. Returns (photons, non-finite dropped)."""
    med, m, state = where
    n = 0
    nbad = 0
    l0, l1, l2 = out.phi[hh, 0, y, x, 0], out.phi[hh, 0, y, x, 1], out.phi[hh, 0, y, x, 2]
    for i in range(min(grid_query(grid, dg, r, scr.buf), scr.buf.shape[0])):
        v = scr.buf[i]
        if not _admit(lp, v, prm, med, m, state):
            continue
        ph = hg_eval(g, dc[0] * lp.d_in[v, 0] + dc[1] * lp.d_in[v, 1] + dc[2] * lp.d_in[v, 2])
        c0, c1, c2 = cw[0] * ph * lp.beta[v, 0], cw[1] * ph * lp.beta[v, 1], cw[2] * ph * lp.beta[v, 2]
        if not _finite(c0, c1, c2):
            nbad += 1                   # counted among the gathered photons (M), never written
            scr.rows[n] = -1
            n += 1
            continue
        l0 += c0
        l1 += c1
        l2 += c2
        scr.rows[n] = v
        scr.cb[n, 0] = c0
        scr.cb[n, 1] = c1
        scr.cb[n, 2] = c2
        scr.edge[n, 0] = EDGE_UNKNOWN
        n += 1
    out.phi[hh, 0, y, x, 0] = l0
    out.phi[hh, 0, y, x, 1] = l1
    out.phi[hh, 0, y, x, 2] = l2
    return n, nbad


@ir_inline
def _shift_photons(sa, lp, mtab, scr, n, dg, g, r, gv, og, stack, out, hh, y, x):
    """The photons of one distance sample (scratch rows 0..n) shifted to the four neighbours' gather
    points og[j], photon by photon: a photon's recorded edge and specular chain are built once for
    its four shifts. D_j, S_j and the shift counts are summed in the row scratch (scr.acc, scr.cnt)
    in photon order -- each buffer element sees the same additions in the same order as one write
    per term -- and written once. Inlined: a call passing the scene and the light records costs
    more than a null shift (~0.7 us measured for gvpm_light.reconnect as a call against inlined,
    on the spot medium)."""
    acc, cnt = scr.acc, scr.cnt
    for i in range(1, 9):
        for c in range(3):
            acc[i, c] = out.phi[hh, i, y, x, c]
    for q in range(N_COUNTS):
        cnt[q] = 0
    nbad = 0
    for i in range(n):
        v = scr.rows[i]
        if v < 0:
            continue
        scr.chain.state[0] = CHAIN_UNKNOWN
        for j in range(4):
            nbad += _shift_one(sa, lp, mtab, scr, i, v, dg, g, r, gv, og, j, stack)
    for i in range(1, 9):
        for c in range(3):
            out.phi[hh, i, y, x, c] = acc[i, c]
    for q in range(N_COUNTS):
        out.count[hh, q, y, x] += cnt[q]
    return nbad


@ir_inline
def _shift_one(sa, lp, mtab, scr, i, v, dg, g, r, gv, og, j, stack):
    """Photon v (scratch row i, base term scr.cb[i]) shifted to neighbour j's gather point og[j]:
    its terms and outcome added to the sums (:func:`add_shift`). Returns the non-finite terms
    dropped (counted, never written)."""
    c_b = (scr.cb[i, 0], scr.cb[i, 1], scr.cb[i, 2])
    c_o = (0.0, 0.0, 0.0)
    ratio = 0.0
    ok = og[j, 0] > 0.0
    kind = NULL
    walked = False
    nbad = 0
    if ok:
        dp = (og[j, 1], og[j, 2], og[j, 3])
        b2, kind = photon_shift((lp.pos[v, 0], lp.pos[v, 1], lp.pos[v, 2]), dg, dp, r, gv.mixed)
        f3, rl, w_in = (1.0, 1.0, 1.0), 1.0, (lp.d_in[v, 0], lp.d_in[v, 1], lp.d_in[v, 2])
        if kind != NULL:
            if scr.edge[i, 0] == EDGE_UNKNOWN:
                store_edge(scr.edge, i, base_edge(sa, lp, v, stack))
            status, f3, rl, w_in, walked = complete_volume_photon(sa, lp, mtab, v, b2, load_edge(scr.edge, i), r,
                                                                  scr.chain, stack, (dp, r if gv.relaxed else 0.0))
            ok = status == OK
        if ok:
            ph = hg_eval(g, og[j, 4] * w_in[0] + og[j, 5] * w_in[1] + og[j, 6] * w_in[2])
            c_o = (og[j, 7] * ph * lp.beta[v, 0] * f3[0], og[j, 8] * ph * lp.beta[v, 1] * f3[1],
                   og[j, 9] * ph * lp.beta[v, 2] * f3[2])
            ratio = og[j, 10] * rl
            if not (_finite(c_o[0], c_o[1], c_o[2]) and math.isfinite(ratio)):
                nbad += 1                                      # counted, never written
                ok = False
            elif not ratio > 0.0:
                ok = False
    wgt = 1.0
    if ok:
        # Eq. 19, balance heuristic; a null shift's is the camera side's, computed once per sample
        wgt = og[j, 11] if kind == NULL else mis_weight_from_log_ratio(math.log(ratio))
    add_shift(scr.acc, scr.cnt, j, ok, kind, walked, c_o, c_b, wgt)
    return nbad


@inlined
def add_shift(acc, cnt, j, ok, kind, walked, c_o, c_b, wgt):
    """Neighbour j's terms of one photon into a pixel half's sums (``acc`` rows as the buffers:
    D_j at 1 + j, S_j at 5 + j) and its outcome into the counts ``cnt`` (C_*): D_j += w (c_o - c_b),
    S_j += w c_o, or for a failed shift D_j -= c_b (w = 1, no offset; PHOTONS.md Sec. 0.2).
    G-VPM's and G-BRE's camera passes."""
    if not ok:
        cnt[C_FAILED] += 1
        for c in range(3):
            acc[1 + j, c] += -1.0 * c_b[c]
        return
    cnt[C_NULL if kind == NULL else C_MANIFOLD if walked else C_RECONNECTED] += 1
    if kind == REFLECTED:
        cnt[C_MIXED] += 1
    for c in range(3):
        acc[1 + j, c] += wgt * (c_o[c] - c_b[c])
        acc[5 + j, c] += wgt * c_o[c]
