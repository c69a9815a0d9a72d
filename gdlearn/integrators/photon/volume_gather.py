"""The camera pass of the volumetric photon estimators: every pixel's two gather paths, in parallel rows.

A pixel takes two camera samples a pass (sample 2 i + hh, half hh of pass i), as surface photon
mapping does (:mod:`gdlearn.integrators.photon.sppm`): half hh gathers only the photons of the
light paths of half hh, so the two halves are independent estimates at the same radii. Each camera
sample traces a path with long beams (``gdlearn.integrators.photon.camera_beams.beam_path``)
and returns, per half:

* the emission its path saw (exact, no photon), unless ``transport`` is media-only;
* the surface photon estimate at the gather point (the SPPM density sum, its photon count), unless
  media-only;
* the medium estimate along its beams: VPM's K distance samples (sum and photon count; the caller
  divides by the ball volume of the pixel's radius) or the BRE over every beam (kernel included).

The structures come in separately (numba's parfor refuses a tuple of NamedTuples as an argument):
surface hash grids ``sga``, ``sgb``; VPM's volume hash grids ``vga``, ``vgb``; the BRE's
bounding-box hierarchies ``bba``, ``bbb``. An estimator passes empty ones for what it does not use.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from gdlearn.kernels.accel.bvh import STACK_SIZE
from gdlearn.kernels.arrays import borrow, borrowed
from gdlearn.kernels.camera import camera_ray
from gdlearn.kernels.rng import path_state, rand_at
from gdlearn.kernels.threads import next_rows, run_rows
from gdlearn.kernels.jit import block, ir_inline
from gdlearn.photons.trace import _borrow_rec
from gdlearn.kernels.media.medium import medium_params, sample_distance_truncated_1
from gdlearn.integrators.photon.camera_beams import BEAM_COLS, BEAM_D, BEAM_MED, BEAM_O, BEAM_S, MAX_BEAMS, beam_path
from gdlearn.integrators.photon.gather import _borrow_grid, density, pixel_angle, put_finite
from gdlearn.integrators.photon.volume_estimates import bre_beam, vpm_beam

#: VolumeParams.method
VPM, BRE2D, BRE3D = 0, 2, 3
#: the random dimension of the radius probe (used only by the footprint pass's sample index)
D_PROBE = 1 << 23


class VolumeParams(NamedTuple):
    method: int           # VPM, BRE2D or BRE3D
    samples: int          # VPM: distance samples per camera path
    surfaces: bool        # also the surface gather and the emission (False: --transport media)
    knn: int              # VPM: k-NN radius at each distance sample, capped at the pixel's radius (0: that radius)


class VolumeOut(NamedTuple):
    phi: np.ndarray       # (2, H, W, 3): surface photon sum (SPPM's Phi) per half
    m: np.ndarray         # (2, H, W): surface photons found
    le: np.ndarray        # (2, H, W, 3): emission seen through the specular chain
    foot: np.ndarray      # (2, H, W): pixel footprint at the gather point (0: none)
    bad: np.ndarray       # (H,): non-finite terms dropped
    phiv: np.ndarray      # (2, H, W, 3): medium estimate (VPM with a fixed radius: without 1 / V(r))
    mv: np.ndarray        # (2, H, W): volume photons found
    probe: np.ndarray     # (2, H, W, 3): a point on the first beam at a free-flight distance (NaN: no beam)


def new_out(h: int, w: int) -> VolumeOut:
    z3, z = (lambda: np.zeros((2, h, w, 3))), (lambda: np.zeros((2, h, w)))
    return VolumeOut(z3(), z(), z3(), z(), np.zeros(h, np.int64), z3(), z(), np.full((2, h, w, 3), np.nan))


def gather_rows(sa, lp, sgrids, vgrids, bbhs, radius, gprm, vprm, seed, sample0, r_surf, r_vol, out):
    """Every pixel's two camera samples into ``out``; ``r_surf``, ``r_vol`` (H x W) are the
    surface and VPM radii per pixel, ``radius`` the BRE radius per light-vertex row. The rows run on
    threads in dynamic chunks (``kernels.threads.run_rows``), as G-VPM's and G-BRE's camera passes
    do, so the primal and the gradient estimators are timed on the same footing."""
    run_rows(lambda counter, step: _gather_rows(sa, lp, sgrids[0], sgrids[1], vgrids[0], vgrids[1], bbhs[0], bbhs[1],
                                                radius, gprm, vprm, seed, sample0, r_surf, r_vol, out, counter, step),
             r_surf.shape[0])


@block
def _out(o):
    return VolumeOut(borrow(o.phi), borrow(o.m), borrow(o.le), borrow(o.foot), borrow(o.bad), borrow(o.phiv),
                     borrow(o.mv), borrow(o.probe))


@block(nogil=True)
def _gather_rows(sa, lp, sga, sgb, vga, vgb, bba, bbb, radius, gprm, vprm, seed, sample0, r_surf, r_vol, out, counter,
                 step):
    """One thread's share of :func:`gather_rows`: chunks of ``step`` rows taken from ``counter``."""
    # borrowed views: no atomic reference counts shared by the threads (kernels.arrays.borrow)
    sb, lb, sgrids, vgrids, rb, ob = borrowed(sa), _borrow_rec(lp), (_borrow_grid(sga), _borrow_grid(sgb)), \
        (_borrow_grid(vga), _borrow_grid(vgb)), borrow(radius), _out(out)
    h = r_surf.shape[0]
    while True:
        y0, y1 = next_rows(counter, step, h)
        if y0 == y1:
            return
        for y in range(y0, y1):
            ob.bad[y] = _row(sb, lb, sgrids, vgrids, (bba, bbb), rb, gprm, vprm, seed, sample0, r_surf, r_vol, ob, y)


@ir_inline
def _row(sa, lp, sgrids, vgrids, bbhs, radius, gprm, vprm, seed, sample0, r_surf, r_vol, out, y):
    w = r_surf.shape[1]
    nbad = 0
    stack = np.empty(STACK_SIZE, dtype=np.int32)
    beams = np.empty((MAX_BEAMS, BEAM_COLS))
    bstate = np.empty((MAX_BEAMS, 2), dtype=np.int64)
    # the candidates of one query: every photon of the larger half at most (BRE: the hierarchies, VPM: the grids)
    buf = np.empty(max(1, bbhs[0].order.shape[0], bbhs[1].order.shape[0], vgrids[0].order.shape[0],
                       vgrids[1].order.shape[0]), dtype=np.int64)
    kd = np.empty(max(1, vprm.knn))
    kv = np.empty(max(1, vprm.knn), dtype=np.int64)
    for x in range(w):
        for hh in range(2):
            h = path_state(seed, y * w + x, sample0 + hh)
            fx = x + rand_at(h, 0)
            fy = y + rand_at(h, 1)
            o, d, tmax = camera_ray(sa.camera, fx, fy)
            ok, p, ng, frame, wi, mid, beta, state, m, dist, le, nb = beam_path(sa, gprm, h, o, d, stack, beams,
                                                                                bstate)
            _clear(out, hh, y, x)
            if vprm.surfaces:
                for c in range(3):
                    out.le[hh, y, x, c] = le[c]
            if ok and vprm.surfaces:
                out.foot[hh, y, x] = dist * pixel_angle(sa.camera, fx, fy, d)
                r = r_surf[y, x]
                if r > 0.0:
                    phi, cnt = density(lp, sgrids[hh], gprm, (p, ng, frame, wi, sa.materials[mid], state, m), r)
                    if put_finite(out.phi, hh, y, x, (beta[0] * phi[0], beta[1] * phi[1], beta[2] * phi[2])):
                        out.m[hh, y, x] = cnt
                    else:
                        nbad += 1
            if nb == 0:
                continue
            _probe(sa.media, beams, rand_at(h, D_PROBE), out.probe, hh, y, x)
            a, cnt = _medium(sa, lp, vgrids[hh], bbhs[hh], radius, gprm, vprm, h, beams, bstate, nb, r_vol[y, x],
                             buf, kd, kv)
            if put_finite(out.phiv, hh, y, x, a):
                out.mv[hh, y, x] = cnt
            else:
                nbad += 1
    return nbad


@block
def _medium(sa, lp, vgrid, bbh, radius, gprm, vprm, h, beams, bstate, nb, r, buf, kd, kv):
    if vprm.method == VPM:
        if not r > 0.0:
            return (0.0, 0.0, 0.0), 0
        return vpm_beam(sa.media, lp, vgrid, gprm, h, beams, bstate, nb, r, vprm.samples, vprm.knn, kd, kv, buf)
    a = (0.0, 0.0, 0.0)
    cnt = 0
    for b in range(nb):
        e, c = bre_beam(sa.media, lp, bbh, radius, gprm, h, beams, bstate, b, vprm.method, buf)
        a = (a[0] + e[0], a[1] + e[1], a[2] + e[2])
        cnt += c
    return a, cnt


@block
def _probe(media, beams, u, probe, hh, y, x):
    """A point on the first beam at a free-flight distance (truncated to the beam): where the camera
    sees the medium, for the default volume radius (the photon density there)."""
    sig = medium_params(media[int(beams[0, BEAM_MED])])[0]
    sbar = (sig[0] + sig[1] + sig[2]) / 3.0
    s = beams[0, BEAM_S]
    if not (sbar > 0.0 or s < math.inf):
        return
    t, pdf = sample_distance_truncated_1(sbar, s, u)
    for c in range(3):
        probe[hh, y, x, c] = beams[0, BEAM_O + c] + t * beams[0, BEAM_D + c]


@block
def _clear(out, hh, y, x):
    for c in range(3):
        out.le[hh, y, x, c] = 0.0
        out.phi[hh, y, x, c] = 0.0
        out.phiv[hh, y, x, c] = 0.0
    out.m[hh, y, x] = 0.0
    out.mv[hh, y, x] = 0.0
    out.foot[hh, y, x] = 0.0
    for c in range(3):
        out.probe[hh, y, x, c] = math.nan
