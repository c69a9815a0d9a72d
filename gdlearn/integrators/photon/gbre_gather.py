"""The camera pass of the gradient-domain beam radiance estimate, G-BRE (Gruson et al. 2018, Sec. 5.1,
Fig. 6b/6d; PHOTONS.md Sec. 5.6, 5.9-5.11), light transport ending in the medium.

Per pixel and half (camera sample 2 i + hh of pass i, as :mod:`gdlearn.integrators.photon.volume_gather`):

1. **Base**: the camera path with long beams and, on every beam, the BRE of
   :func:`gdlearn.integrators.photon.volume_estimates.bre_beam` -- the same photons (the
   bounding-box hierarchy's), the same kernel weights and, in 3D, the same random number per
   (beam, photon row) for the chord point, so the base buffer *is* the BRE's medium estimate.
2. **Offset camera subpaths**: G-VPM's random replay from the neighbour's film position
   (``gdlearn.integrators.photon.gvpm_gather._offset_path``: same structure or the shift
   fails; a neighbour outside the image is a failed shift, PHOTONS.md E12). Every beam is gathered,
   none is selected, so there is no beam-selection probability in the MIS ratio.
3. **Camera distance copy** (Eq. 14-15): the gather point's t on the offset's beam b; fails where that
   beam is shorter.
4. **Photon shift** and light subpath, per kernel:

   - *3D* (:func:`shift_3d`, the paper's): d = c + t w_c with t uniform on b's chord; G-VPM's mixed
     (Eq. 16) or simple shift relative to (d, d'). Null criterion (Sec. 5.6): ``|d' - b| < r`` and
     t <= s'. The offset contribution keeps the base's chord density (``f(T x) |J| / p(x)``); the MIS
     ratio takes the offset's own chord density 1 / (2 D t'), D t' = sqrt(r^2 - d'_perp^2) of b'
     against the offset ray (PHOTONS.md Sec. 5.6 [analysis]): ``[D t / D t'] x`` the light side's.
     A chord D t' of 0 (b' on the offset kernel's boundary, a null set) fails the shift.
   - *2D* (:func:`shift_2d`): d is the photon's projection on the beam; the offset photon is the
     rigid ray-frame copy (:func:`gdlearn.shifts.volume_photon.ray_frame_copy`, ``|J| = 1``), so the
     kernel value is the same at d'; every photon is reconnected. No mixed shift: two discs facing
     different rays overlap in a null set. The MIS ratio is the light side's alone (t is no
     random variable of a 2D query).

   Reconnections go through :func:`gdlearn.integrators.photon.gvpm_light.reconnect_edge` (visibility
   over the whole segment, null interfaces crossed as the base edge did); a photon whose parent is
   specular is completed by the manifold walk instead (Sec. 4.3,
   :func:`gdlearn.integrators.photon.photon_manifold.manifold_volume_photon`), as G-VPM's.
5. **Photon subsets** (Sec. 6.1, PHOTONS.md Sec. 5.10, ``subsets``): pixel (x, y) of parity
   g = (x + y) mod 2 gathers, for its base *and* its shifts, only the photons of light paths whose
   index has parity g, weighted by ``wsub[hh, g]`` (the half's path count over the subset's: 2 for an
   even count). Neighbours have opposite parities, so the forward shift of a pair uses one subset
   and the backward shift the other; both are unbiased for the same integral, and the MIS weights
   are functions of the paths alone, so they stay complementary.

Organisation (for speed; benchmarks/README.md, G-BRE section), G-VPM's recipe
(:mod:`gdlearn.integrators.photon.gvpm_gather`): a photon's recorded edge a -> b
(``gvpm_light.base_edge``) is walked at most once for its four neighbours, and only if one of them
reconnects; a pixel half's L, D_k, S_k and shift counts are summed in a row scratch in photon order
(beam by beam, photon by photon, neighbour by neighbour: each buffer sees the same additions in the
same order as one write per term) and written once; the per-photon helpers are inlined; a camera
sample's offset camera paths are traced when its first photon is found. The buffers are bit for
bit those of the straightforward kernel (tests/_gbre_reference.py, whose buffers
tests/golden/passes.py records and tests/test_photon_fast_passes.py compares).

Buffers as G-VPM's (:class:`gdlearn.integrators.photon.gvpm_gather.GvpmOut`): L, D_k, S_k with the
kernel included, ``m`` the base photons, ``count`` the shifts null / mixed / reconnected / failed /
manifold (walked).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from gdlearn.kernels.accel.bvh import STACK_SIZE
from gdlearn.kernels.arrays import borrow, borrowed
from gdlearn.kernels.camera import camera_ray
from gdlearn.kernels.jit import block, inlined, ir_inline
from gdlearn.kernels.media.medium import medium_params, transmittance
from gdlearn.kernels.media.phase import hg_eval
from gdlearn.kernels.rng import path_state, rand_at
from gdlearn.kernels.threads import next_rows, run_rows
from gdlearn.photons import bbh as bbh_mod
from gdlearn.photons.trace import _borrow_rec
from gdlearn.integrators.photon.camera_beams import BEAM_COLS, BEAM_D, BEAM_MED, BEAM_O, BEAM_S, BEAM_W, MAX_BEAMS, \
    beam_path
from gdlearn.integrators.photon.photon_shift_loop import finite3
from gdlearn.integrators.photon.gvpm_gather import N_COUNTS, GvpmOut, add_shift, offset_paths
from gdlearn.integrators.photon.gvpm_light import EDGE_COLS, EDGE_UNKNOWN, OK, base_edge, load_edge, reconnect, \
    store_edge
from gdlearn.integrators.photon.photon_manifold import CHAIN_UNKNOWN, VolumeChain, complete_volume_photon, \
    new_volume_chain
from gdlearn.integrators.photon.volume_estimates import KERNEL_2D, _admit, beam_kernel
from gdlearn.shifts.mis import mis_weight_from_log_ratio
from gdlearn.shifts.volume_photon import NULL, TRANSLATED, camera_distance_copy, chord_half, photon_shift, \
    ray_frame_copy


class GbreParams(NamedTuple):
    kernel: int           # KERNEL_2D or KERNEL_3D (volume_estimates)
    mixed: bool           # 3D: the mixed shift (Eq. 16); False: the simple shift
    subsets: bool         # photon subsets on a checkerboard (module docstring, item 5)
    relaxed: bool         # the relaxed manifold walk (Sec. 6.1; photon_manifold.shift_volume_chain); False: exact


class Scratch(NamedTuple):
    """A row's scratch arrays, allocated once per row (numba would allocate them per call otherwise)."""
    buf: np.ndarray       # the hierarchy's candidates (as many as it has photons)
    oa: np.ndarray        # (3,): the current beam's origin, as an array for bbh.collect
    da: np.ndarray        # (3,): its direction
    acc: np.ndarray       # (9, 3): the pixel half's L, D_k, S_k, summed in photon order, written once
    cnt: np.ndarray       # (N_COUNTS,) int64: its shift counts null / mixed / reconnected / failed / manifold
    edge: np.ndarray      # (1, EDGE_COLS): the current photon's recorded edge a -> b, walked at most once
    traced: np.ndarray    # (1,) bool: the camera sample's offset camera paths are traced (offset_paths)
    chain: VolumeChain    # the current photon's specular chain, built once for its four neighbours


_ZERO = (0.0, 0.0, 0.0)
_ONE = (1.0, 1.0, 1.0)


@inlined
def _along(o, d, t):
    return (o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2])


@inlined
def _place_3d(lp, v, o, d, o_off, d_off, t, s_off, r, half, mixed):
    """Where G-BRE-3D puts photon row v (gathered at d = o + t d, chord half-length ``half`` on the
    base beam) for the offset beam (o', d', length s'): (ok, kind, b', half, half'), half' the offset
    beam's chord through b' -- the MIS ratio's offset chord density 1 / (2 half'). Module docstring,
    item 4: the camera distance copy (Eq. 14-15), the mixed (Eq. 16) or simple shift relative to
    (d, d'), and the null criterion |d' - b'| < r of Sec. 5.6."""
    if not camera_distance_copy(t, s_off)[0]:
        return False, NULL, _ZERO, half, 0.0
    b = (lp.pos[v, 0], lp.pos[v, 1], lp.pos[v, 2])
    dg, dp = _along(o, d, t), _along(o_off, d_off, t)
    b2, kind = photon_shift(b, dg, dp, r, mixed)
    e = (b2[0] - dp[0], b2[1] - dp[1], b2[2] - dp[2])
    half2 = chord_half(r, bbh_mod.perp(o_off, d_off, b2)[1])
    if not (e[0] * e[0] + e[1] * e[1] + e[2] * e[2] < r * r and half2 > 0.0 and half > 0.0):
        return False, kind, b2, half, half2       # b' on K''s boundary: a null set, its reverse weighs 0
    return True, kind, b2, half, half2


@inlined
def _place_2d(lp, v, o, d, o_off, d_off, t, s_off):
    """Where G-BRE-2D puts photon row v (its projection on the base beam at t): the ray-frame copy
    (``|J| = 1``, the same kernel value at d'), as ``_place_3d``'s tuple with both chord lengths 1
    (t is no random variable of a 2D query, so the camera side adds nothing to the MIS ratio)."""
    if not camera_distance_copy(t, s_off)[0]:
        return False, TRANSLATED, _ZERO, 1.0, 1.0
    b = (lp.pos[v, 0], lp.pos[v, 1], lp.pos[v, 2])
    ok, b2 = ray_frame_copy(b, _along(o, d, t), d, _along(o_off, d_off, t), d_off)
    return ok, TRANSLATED, b2, 1.0, 1.0


@block
def shift_3d(sa, lp, v, o, d, o_off, d_off, t, s_off, r, mixed, stack):
    """G-BRE-3D's shift of photon row v gathered at d = o + t d on the base beam, to the offset beam
    (o', d', length s'): (ok, kind, beta_b' / beta_b per channel, offset over base density ratio
    of Eq. 19, the direction the offset photon arrives along). Module docstring, item 4. (The
    camera pass does the same through ``_place_3d`` and ``_light_side``, the recorded edge
    shared by the neighbours; this is its one-photon form, for tests/test_gbre.py.)"""
    half = chord_half(r, bbh_mod.perp(o, d, (lp.pos[v, 0], lp.pos[v, 1], lp.pos[v, 2]))[1])
    ok, kind, b2, half, half2 = _place_3d(lp, v, o, d, o_off, d_off, t, s_off, r, half, mixed)
    if not ok:
        return False, kind, _ONE, 0.0, _ZERO
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
    ok, kind, b2, _, _ = _place_2d(lp, v, o, d, o_off, d_off, t, s_off)
    if not ok:
        return False, TRANSLATED, _ONE, 0.0, _ZERO
    status, f3, rl, w_in = reconnect(sa, lp, v, b2, stack)
    if status != OK:
        return False, TRANSLATED, _ONE, 0.0, _ZERO
    return True, TRANSLATED, f3, rl, w_in


def gbre_rows(sa, lp, bbhs, mtab, r, prm, gp, wsub, seed, sample0, out):
    """Every pixel's two camera samples (sample0 + hh) and their four shifts into ``out`` (a
    :class:`~gdlearn.integrators.photon.gvpm_gather.GvpmOut`); ``bbhs`` holds four hierarchies, (half 0, parity 0), (0, 1), (1, 0), (1, 1)
    -- without subsets each half's twice --, ``r`` is the pass's global radius, ``wsub`` (2 x 2) the
    subset weights per half and parity, ``mtab`` the specular shapes the manifold walk moves
    (``gpt_surface.manifold.manifold_table``). The rows run on threads (``kernels.threads.run_rows``),
    not in a parallel kernel, and the steps below the row driver are IR-inlined into it: numba
    compiles a function it does not IR-inline on its own and again inside every caller above it
    (``kernels/jit.py``), and this pass's manifold walk made each of those levels cost 10-90 s of a
    cold compile (benchmarks/README.md, "G-VPM's and G-BRE's cold compile")."""
    run_rows(lambda counter, step: _gbre_rows(sa, lp, bbhs[0], bbhs[1], bbhs[2], bbhs[3], mtab, r, prm, gp, wsub, seed,
                                              sample0, out, counter, step), out.bad.shape[0])


@block(nogil=True)
def _gbre_rows(sa, lp, b00, b01, b10, b11, mtab, r, prm, gp, wsub, seed, sample0, out, counter, step):
    """One thread's share of :func:`gbre_rows`: chunks of ``step`` rows taken from ``counter``."""
    # borrowed views: no atomic reference counts shared by the threads (kernels.arrays.borrow)
    sb, lb, ob = borrowed(sa), _borrow_rec(lp), GvpmOut(borrow(out.phi), borrow(out.m), borrow(out.count),
                                                        borrow(out.bad))
    h = out.bad.shape[0]
    while True:
        y0, y1 = next_rows(counter, step, h)
        if y0 == y1:
            return
        for y in range(y0, y1):
            ob.bad[y] = _row(sb, lb, (b00, b01, b10, b11), mtab, r, prm, gp, wsub, seed, sample0, ob, y)


@ir_inline
def _row(sa, lp, bbhs, mtab, r, prm, gp, wsub, seed, sample0, out, y):
    """Row y's scratch, allocated once, and the row's pixels (:func:`_pixels`)."""
    nmax = 1
    for i in range(4):
        nmax = max(nmax, bbhs[i].order.shape[0])
    work = (np.empty(STACK_SIZE, dtype=np.int32), np.empty((MAX_BEAMS, BEAM_COLS)),
            np.empty((MAX_BEAMS, 2), dtype=np.int64), np.empty((4, MAX_BEAMS, BEAM_COLS)),
            np.empty((4, MAX_BEAMS, 2), dtype=np.int64), np.zeros(4, dtype=np.bool_))
    scr = Scratch(np.empty(nmax, dtype=np.int64), np.empty(3), np.empty(3), np.empty((9, 3)),
                  np.empty(N_COUNTS, dtype=np.int64), np.empty((1, EDGE_COLS)), np.zeros(1, dtype=np.bool_),
                  new_volume_chain())
    return _pixels(sa, lp, bbhs, mtab, r, prm, gp, wsub, seed, sample0, out, y, work, scr)


@block
def _pixels(sa, lp, bbhs, mtab, r, prm, gp, wsub, seed, sample0, out, y, work, scr):
    """Every pixel of row y, with the row's scratch borrowed (kernels/arrays.py: no reference count;
    :func:`_row`'s arrays outlive this call). A call of its own, not IR-inlined into :func:`_row`:
    inlined, the owning arrays would be released after their last use -- the borrowing --, and the
    views would read freed memory (another thread's rows, seen as a nondeterministic pass). Counted,
    every inlined helper that receives an array increments and decrements its count atomically: ~30 %
    of the fog box's pass (perf, 48^2)."""
    hgt, w = out.m.shape[1], out.m.shape[2]
    nbad = 0
    stack, beams, bstate = borrow(work[0]), borrow(work[1]), borrow(work[2])
    obeams, obstate, o_ok = borrow(work[3]), borrow(work[4]), borrow(work[5])
    ch = scr.chain
    scr = Scratch(borrow(scr.buf), borrow(scr.oa), borrow(scr.da), borrow(scr.acc), borrow(scr.cnt),
                  borrow(scr.edge), borrow(scr.traced),
                  VolumeChain(borrow(ch.state), borrow(ch.rows), borrow(ch.X), borrow(ch.shapes), borrow(ch.etas),
                              borrow(ch.refr), borrow(ch.targets), borrow(ch.S), borrow(ch.A), borrow(ch.det)))
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
            scr.traced[0] = False           # the offset camera paths wait for the first photon (_beam)
            _load_sums(out, hh, y, x, scr)
            cnt = 0
            for b in range(nb):
                c, bad = _beam(sa, lp, bbhs[2 * hh + par], mtab, prm, gp, h, (beams, bstate, b, nb),
                               (obeams, obstate, o_ok), (fx, fy, x, y, w, hgt), r, wsub[hh, par], scr, stack)
                cnt += c
                nbad += bad
            _store_sums(out, hh, y, x, scr)
            out.m[hh, y, x] = cnt
    return nbad


@inlined
def _load_sums(out, hh, y, x, scr):
    """Start the pixel half's sums where its buffers are (zero: each pixel half is written once)."""
    for i in range(9):
        for c in range(3):
            scr.acc[i, c] = out.phi[hh, i, y, x, c]
    for i in range(N_COUNTS):
        scr.cnt[i] = 0


@inlined
def _store_sums(out, hh, y, x, scr):
    for i in range(9):
        for c in range(3):
            out.phi[hh, i, y, x, c] = scr.acc[i, c]
    for i in range(N_COUNTS):
        out.count[hh, i, y, x] += scr.cnt[i]


@ir_inline
def _beam(sa, lp, bbh, mtab, prm, gp, h, base, offs, film, r, ws, scr, stack):
    """The BRE along beam b (bre_beam's photons, kernel and random numbers) and every photon's four
    shifts, into the pixel half's sums: (photons counted, non-finite terms dropped)."""
    beams, bstate, b, nb = base
    med = int(beams[b, BEAM_MED])
    sig, alb, g = medium_params(sa.media[med])
    for c in range(3):
        scr.oa[c] = beams[b, BEAM_O + c]
        scr.da[c] = beams[b, BEAM_D + c]
    o = (scr.oa[0], scr.oa[1], scr.oa[2])
    d = (scr.da[0], scr.da[1], scr.da[2])
    s = beams[b, BEAM_S]
    m = int(bstate[b, 1])
    state = bstate[b, 0]
    n = bbh_mod.collect(bbh, scr.oa, scr.da, s, gp.kernel, scr.buf)
    acc = scr.acc
    cnt = 0
    nbad = 0
    for i in range(min(n, scr.buf.shape[0])):
        v = scr.buf[i]
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
        if not finite3(c_b):
            nbad += 1
            continue
        for c in range(3):
            acc[0, c] += c_b[c]
        pre = (tr[0] * lp.beta[v, 0] * kw * ws, tr[1] * lp.beta[v, 1] * kw * ws, tr[2] * lp.beta[v, 2] * kw * ws)
        if not scr.traced[0]:                 # most camera samples find no photon at G-BRE's small kernel
            offset_paths(sa, prm, h, film, stack, beams, bstate, nb, offs)
            scr.traced[0] = True
        # the base's chord half-length through v's ball (3D), from the same perp() as the kernel's
        nbad += _shift_photon(sa, lp, mtab, v, gp, g, (o, d, b, t, r, chord_half(r, dp2)), (offs[0], offs[2]), pre,
                              c_b, scr, stack)
    return cnt, nbad


@ir_inline
def _light_side(sa, lp, mtab, v, kind, b2, r, scr, stack, relax):
    """(ok, beta_b' / beta_b per channel, light-side density ratio, arrival direction at b', walked)
    of photon row v moved to b': unchanged for a null shift (T(y) = y), else reconnected from its
    parent with the recorded edge a -> b walked on the first neighbour that needs it and kept in
    ``scr.edge`` for the others (``gvpm_light.reconnect_edge``: the same arithmetic as ``reconnect``),
    or -- a specular parent -- completed by the manifold walk (Gruson et al. 2018 Sec. 4.3,
    :func:`gdlearn.integrators.photon.photon_manifold.manifold_volume_photon`; ``relax``: its
    (d', radius) of the relaxed walk, radius 0 for the exact one)."""
    if kind == NULL:
        return True, _ONE, 1.0, (lp.d_in[v, 0], lp.d_in[v, 1], lp.d_in[v, 2]), False
    if scr.edge[0, 0] == EDGE_UNKNOWN:
        store_edge(scr.edge, 0, base_edge(sa, lp, v, stack))
    status, f3, rl, w_in, walked = complete_volume_photon(sa, lp, mtab, v, b2, load_edge(scr.edge, 0), r, scr.chain,
                                                          stack, relax)
    return status == OK, f3, rl, w_in, walked


@ir_inline
def _shift_photon(sa, lp, mtab, v, gp, g, q, offs, pre, c_b, scr, stack):
    """Photon row v (base term c_b; ``pre`` = T(t) beta kernel weight, per channel; q = base beam
    (o, d), its index b, the photon's t, the radius and its chord half-length) shifted to the four
    offset beams: D_k, S_k and the counts added to the pixel half's sums (scr.acc, scr.cnt) in the
    order the straightforward kernel wrote them. Returns the non-finite terms dropped."""
    o, d, b, t, r, half = q
    obeams, o_ok = offs
    acc, cnt = scr.acc, scr.cnt
    scr.edge[0, 0] = EDGE_UNKNOWN
    scr.chain.state[0] = CHAIN_UNKNOWN
    nbad = 0
    for j in range(4):
        ok = o_ok[j]
        kind = NULL
        c_o = _ZERO
        ratio = 0.0
        f3, rl, w_in = _ONE, 1.0, _ZERO
        walked = False
        if ok:
            o2 = (obeams[j, b, BEAM_O], obeams[j, b, BEAM_O + 1], obeams[j, b, BEAM_O + 2])
            d2 = (obeams[j, b, BEAM_D], obeams[j, b, BEAM_D + 1], obeams[j, b, BEAM_D + 2])
            if gp.kernel == KERNEL_2D:
                ok, kind, b2, num, den = _place_2d(lp, v, o, d, o2, d2, t, obeams[j, b, BEAM_S])
            else:
                ok, kind, b2, num, den = _place_3d(lp, v, o, d, o2, d2, t, obeams[j, b, BEAM_S], r, half, gp.mixed)
            if ok:
                relax = (_along(o2, d2, t), r if gp.relaxed else 0.0)     # d': the offset gather point
                ok, f3, rl, w_in, walked = _light_side(sa, lp, mtab, v, kind, b2, r, scr, stack, relax)
            if ok:
                # f(T x) |J| / p(x): the offset camera weight, the phase at d' for the (new) arrival
                # direction, the base's T(t) (same t, same medium) and the base's kernel density;
                # Eq. 19's ratio: the light side's times (3D) the chord densities [D t / D t']
                ph = hg_eval(g, d2[0] * w_in[0] + d2[1] * w_in[1] + d2[2] * w_in[2])
                c_o = (obeams[j, b, BEAM_W] * ph * pre[0] * f3[0], obeams[j, b, BEAM_W + 1] * ph * pre[1] * f3[1],
                       obeams[j, b, BEAM_W + 2] * ph * pre[2] * f3[2])
                ratio = rl * num / den
                if not (finite3(c_o) and math.isfinite(ratio)):
                    nbad += 1
                    ok = False
                elif not ratio > 0.0:
                    ok = False
        wgt = mis_weight_from_log_ratio(math.log(ratio)) if ok else 1.0      # Eq. 19, balance heuristic
        add_shift(acc, cnt, j, ok, kind, walked, c_o, c_b, wgt)
    return nbad
